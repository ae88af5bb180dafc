"""The fast lane's heads-up: a sim whose physics is done wakes the agent that
sleeps waiting for the reply, so that the wake-up overlaps the rest of the
tick. The results are the msgpack path's; a sim slow after its physics stops
sending them; an error after a heads-up reaches the agent."""

from __future__ import annotations

import os

import numpy as np
import pytest
from equality import assert_same

import remoteenv
from remoteenv.agent.connection import shared_lane_client as shared_lane
from remoteenv.agent.errors import RemoteEnvError

HERE = os.path.dirname(os.path.abspath(__file__))
TAIL_SCENE = os.path.join(HERE, "scenes", "tail_scene.py")


def _heads_ups(env) -> list[int]:
    return [conn.heads_ups for conn in env.unwrapped._session.conns]


def _trajectory(steps: int) -> tuple[list, list[int]]:
    # 1 ms before each tick's physics: the agent's waits outlast its hot window, so it blocks and asks.
    env = remoteenv.RemoteVectorEnv(TAIL_SCENE, 6, envs_per_process=3, max_episode_steps=50, head_s=0.001)
    rng = np.random.default_rng(5)
    try:
        out: list = [env.reset(seed=11)]
        for _ in range(steps):
            out.append(env.step(rng.uniform(-1, 1, size=(6, 2)).astype(np.float32)))
        return out, _heads_ups(env)
    finally:
        env.close()


def test_a_sleeping_agent_is_woken_early_and_gets_the_msgpack_paths_results(monkeypatch):
    # 120 steps cross Reacher's 50-step limit twice: steps that reset worlds are in it.
    lane, heads_ups = _trajectory(120)
    monkeypatch.setattr(shared_lane, "attach", lambda conn: None)
    plain, none = _trajectory(120)
    print(f"heads-ups per sim over 120 steps: {heads_ups} (scheduler-dependent, not asserted)")
    assert none == [0, 0]
    assert_same(lane, plain, "trajectory")


def test_a_sim_slow_after_its_physics_stops_sending_heads_ups():
    # 2 ms before its physics, so the agent has long blocked when it is done.
    slow = remoteenv.RemoteVectorEnv(TAIL_SCENE, 2, envs_per_process=2, head_s=0.002, tail_s=0.002)
    try:
        slow.reset(seed=0)
        for _ in range(20):
            slow.step(np.zeros((2, 2), np.float32))
        # Its first answer shows its tail (2 ms, over HEADS_UP_TAIL_S): at most that one heads-up.
        assert _heads_ups(slow)[0] <= 1, _heads_ups(slow)
    finally:
        slow.close()


def test_an_error_after_the_heads_up_reaches_the_agent_and_the_env_goes_on():
    env = remoteenv.RemoteVectorEnv(TAIL_SCENE, 2, envs_per_process=2, head_s=0.002)
    try:
        env.reset(seed=0)
        for _ in range(3):  # the sim's first answer (its info layout announced) is slow: a few quick ones after it
            env.step(np.zeros((2, 2), np.float32))
        for _ in range(3):
            with pytest.raises(RemoteEnvError) as info:
                env.step(np.array([[0.0, 0.0], [0.5, 0.0]], np.float32))
            assert info.value.kind == "scene" and "refuses the action 0.5" in str(info.value)
            env.reset(seed=1)
        obs, *_ = env.step(np.zeros((2, 2), np.float32))
        assert obs.shape == (2, 10) and np.isfinite(obs).all()
    finally:
        env.close()


def test_an_agent_told_not_to_wait_hot_asks_for_no_heads_up(monkeypatch):
    monkeypatch.setenv("REMOTEENV_NO_SPIN", "1")  # its pipes read it when they are made
    env = remoteenv.RemoteVectorEnv(TAIL_SCENE, 2, envs_per_process=2, head_s=0.002)
    try:
        env.reset(seed=0)
        for _ in range(10):
            env.step(np.zeros((2, 2), np.float32))
        assert _heads_ups(env) == [0]
    finally:
        env.close()
