"""The training-loop benchmark's ``process-floor`` contender steps the same
worlds as remoteenv's vector env (same seeds and actions: the same
observations, rewards and flags, the scene's own stepping, the time limit
and next-step autoreset included), lays them out as remoteenv lays out a
scene whose Python runs per world (a process per CPU, its fastest layout),
and leaves no child behind."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from equality import assert_same_reacher_episodes

from remoteenv.agent.vector.vector_layout import default_envs_per_process, world_slices
from remoteenv.benchmarks.harness.process_floor import ProcessFloorVectorEnv
from remoteenv.benchmarks.train_loop import ratios


def test_the_floor_steps_the_worlds_remoteenv_steps_and_stops_its_children():
    n = 12  # at least 8 worlds per child: two children of 8 and 4 on a 2-CPU machine, one of 12 on one CPU
    floor = ProcessFloorVectorEnv(n, seed=3)
    remote = gym.make_vec("remoteenv/Reacher-v0", n, vectorization_mode="vector_entry_point")
    procs = list(floor._procs)
    try:
        assert floor._slices == world_slices(n, default_envs_per_process(n, stacked_hooks=False))
        obs_f, _ = floor.reset()
        obs_r, _ = remote.reset(seed=3)
        np.testing.assert_array_equal(obs_f, obs_r)
        assert assert_same_reacher_episodes(floor, remote, n) == 2
    finally:
        floor.close()
        remote.close()
    assert all(p.poll() is not None for p in procs)


def test_the_floor_ratios_are_reported_beside_the_anchors():
    rows = [
        {"name": name, "num_envs": 16, "median": rate, "cpu_us_per_step": cpu}
        for name, rate, cpu in (("remoteenv", 300.0, 50.0), ("EnvPool", 200.0, 100.0), ("process-floor", 600.0, 25.0))
    ]
    found = {r["ratio"]: r["value"] for r in ratios(rows)}
    assert found["remoteenv / process-floor, N=16"] == 0.5
    assert found["process-floor / EnvPool, N=16"] == 3.0
