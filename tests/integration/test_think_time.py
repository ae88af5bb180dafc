"""A vector env tells its sims the caller's think time (the doorbell's
``AGENT_THINK_US``) when its sims on this machine take every CPU it may use,
so that they do not wait hot through a policy's inference on the caller's
CPU; with a CPU left free it tells them nothing and they wait as before."""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

from remoteenv.wire.shared_memory.doorbell import AGENT_THINK_US
from remoteenv.wire.shared_memory.hot_wait import usable_cpus

THINK_S = 0.005


def _told_after_a_think(num_envs: int) -> list[int]:
    """Each sim's ``AGENT_THINK_US`` after a step that followed THINK_S of the caller's own work."""
    env = gym.make_vec("remoteenv/Reacher-v0", num_envs, vectorization_mode="vector_entry_point", envs_per_process=2)
    try:
        env.reset(seed=0)
        actions = np.zeros((num_envs, 2), dtype=np.float32)
        for _ in range(3):  # the first steps attach the regions
            env.step(actions)
        time.sleep(THINK_S)  # the caller thinks (sleep lasts at least this long)
        env.step(actions)
        lanes = env.unwrapped._requests.lanes
        return [lanes._bells[p].word(AGENT_THINK_US) for p in range(len(env.unwrapped.slices))]
    finally:
        env.close()


def test_sims_that_take_every_cpu_are_told_the_think_time():
    cpus = usable_cpus()
    if cpus > 8:
        pytest.skip("one sim per CPU of a large machine is more processes than this test should start")
    told = _told_after_a_think(2 * cpus)  # two worlds per sim: one sim per CPU
    assert len(told) == cpus
    assert all(THINK_S * 1e6 <= us < 60e6 for us in told), told


def test_sims_that_leave_a_cpu_free_are_told_nothing():
    cpus = usable_cpus()
    if cpus < 2 or cpus > 8:
        pytest.skip("needs a CPU beside the sims, and few sims")
    told = _told_after_a_think(2 * (cpus - 1))
    assert told == [0] * (cpus - 1)
