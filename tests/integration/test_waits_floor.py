"""The training-loop benchmark's ``waits-floor`` contender steps the same
worlds as remoteenv's vector env (same seeds and actions: the same
observations, rewards and flags, the time limit and next-step autoreset
included), lays them out as remoteenv's default layout does, tells its
children when the caller's update begins, and leaves no child behind."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from equality import assert_same_reacher_episodes

from remoteenv.agent.vector.vector_layout import default_envs_per_process, layout_threads, world_slices
from remoteenv.benchmarks.harness.waits_floor import WaitsFloorVectorEnv
from remoteenv.wire.shared_memory.doorbell import AGENT_AWAY


def test_the_waits_floor_steps_the_worlds_remoteenv_steps_and_stops_its_children():
    n = 12
    floor = WaitsFloorVectorEnv(n, seed=3)
    remote = gym.make_vec("remoteenv/Reacher-v0", n, vectorization_mode="vector_entry_point")
    procs = list(floor._procs)
    try:
        k = default_envs_per_process(n)
        assert floor._slices == world_slices(n, k)
        assert floor.threads == (layout_threads(n, k) or 1)
        obs_f, _ = floor.reset()
        obs_r, _ = remote.reset(seed=3)
        np.testing.assert_array_equal(obs_f, obs_r)
        assert assert_same_reacher_episodes(floor, remote, n) == 2
        floor._away()  # the caller's update begins: every child is told, and the next step clears it
        assert all(bell.word(AGENT_AWAY) == 1 for *_, bell, _views in floor._lanes)
        floor.step(np.zeros((n, 2), dtype=np.float32))
        assert all(bell.word(AGENT_AWAY) == 0 for *_, bell, _views in floor._lanes)
    finally:
        floor.close()
        remote.close()
    assert all(p.poll() is not None for p in procs)
    assert all(p.returncode == 0 for p in procs)
