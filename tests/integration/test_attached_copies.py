"""Issue 19, item 7: a copy or a pickle of an env attached to running sims
never silently drives the same sims.

Rebuilding an attached env from its constructor arguments (what a copy of a
launching env does, with fresh sims) would attach the copy to the *same*
sims: its ``reset`` would move the original's worlds mid-episode. So copying
and pickling an attached env raise a ``TypeError`` saying so, and the
original keeps its episode.
"""

from __future__ import annotations

import copy
import os
import pickle
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest

from remoteenv import OpenAIRemoteEnv, RemoteVectorEnv


@pytest.fixture
def launch_info(tmp_path):
    """One cartpole sim started by ``python -m remoteenv launch``; its launch-info path."""
    out = tmp_path / "launch.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "remoteenv", "launch", "cartpole", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    try:
        deadline = time.monotonic() + 120
        while not out.exists():
            assert proc.poll() is None, f"launch exited early: {proc.stderr.read()}"  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "launch wrote no launch-info file in 120 s"
            time.sleep(0.05)
        yield out
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stderr.close()  # type: ignore[union-attr]


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copy_of_an_attached_env_is_refused_and_the_original_keeps_its_episode(launch_info, how):
    env = gym.make("remoteenv/CartPole-v0", attach=str(launch_info))
    try:
        obs, _ = env.reset(seed=3)
        env.step(1)
        mid_episode, *_ = env.step(1)
        with pytest.raises(TypeError, match="attached to running sims"):
            copy.deepcopy(env) if how == "deepcopy" else pickle.dumps(env)
        # Nothing reached the sim: the original's episode goes on from where it was.
        after, *_ = env.step(0)
        assert not np.allclose(after, obs) and not np.array_equal(after, mid_episode)
    finally:
        env.close()


def test_copies_of_envs_attached_by_the_classmethods_are_refused(launch_info):
    env = OpenAIRemoteEnv.attach(launch_info)
    venv = RemoteVectorEnv.attach(launch_info)
    try:
        with pytest.raises(TypeError, match="cannot pickle or copy"):
            copy.deepcopy(env)
        with pytest.raises(TypeError, match="cannot pickle or copy"):
            pickle.dumps(venv)
    finally:
        venv.close()
        env.close()
