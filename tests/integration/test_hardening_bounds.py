"""Issue 35, items 5 and 8: what a vector env may allocate is bounded, and a
layout is chosen whose frames fit.

- A vector env whose worlds would not fit in this machine's memory is
  refused in one line (a ``LimitError`` with the figures and the fix) by its
  sims, each having built two worlds, not grown until the machine swaps
  (``bench --pixels --pixels-cases 64x100000`` grew past 4 GB in 25 s).
- 16 camera worlds of 1280x1280 pixels (4.9 MB a frame) get a process count
  whose batch replies fit the frame limit (before: refused, 8 worlds a process
  take 39 MB).
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

import remoteenv  # noqa: F401  (registers the ids)
from remoteenv import LimitError
from remoteenv.wire.codec.frame_limits import MAX_MESSAGE_BYTES
from remoteenv.wire.memory import available_bytes


@pytest.mark.skipif(available_bytes() is None, reason="no /proc/meminfo: memory is not bounded here")
def test_a_vector_env_whose_worlds_do_not_fit_in_memory_is_refused_in_one_line():
    start = time.monotonic()
    with pytest.raises(LimitError) as refused:
        gym.make_vec(
            "remoteenv/CartPole-v0",
            num_envs=100_000,
            vectorization_mode="vector_entry_point",
            envs_per_process=50_000,
            obs_mode="pixels",
            startup_timeout=120.0,
        )
    message = str(refused.value)
    print(f"refused after {time.monotonic() - start:.1f} s: {message}")
    assert "\n" not in message and "49998 worlds of about" in message and "more fit here" in message


def test_sixteen_worlds_of_1280_pixels_get_a_layout_whose_frames_fit():
    env = gym.make_vec(
        "remoteenv/CartPole-v0",
        num_envs=16,
        vectorization_mode="vector_entry_point",
        obs_mode="pixels",
        image_size=1280,
        startup_timeout=120.0,
        timeout=120.0,
    )
    try:
        k = env.unwrapped.envs_per_process
        frame = 1280 * 1280 * 3
        print(f"16 worlds of 1280x1280: {k} worlds per process, {-(-16 // k)} processes")
        assert k * frame <= MAX_MESSAGE_BYTES < (k + 1) * frame
        obs, _ = env.reset(seed=0)
        obs, *_ = env.step(np.zeros(16, dtype=np.int64))
        assert obs.shape == (16, 1280, 1280, 3) and obs.dtype == np.uint8
    finally:
        env.close()
