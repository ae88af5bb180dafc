"""The training-loop benchmark's ``agent-floor`` contender drives remoteenv's
own sims through its bare agent end between episode ends and gets what
remoteenv's vector env gets (same seeds and actions: the same observations,
rewards and flags, the time limit and next-step autoreset included), and
leaves no sim behind."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from equality import assert_same_reacher_episodes

from remoteenv.benchmarks.harness.agent_floor import AgentFloorVectorEnv
from remoteenv.benchmarks.train_loop import ratios


def test_the_bare_agent_end_steps_the_worlds_remoteenv_steps_and_stops_its_sims(wait_gone):
    n = 12  # two sims of 8 and 4 worlds on a 2-CPU machine, one of 12 on one CPU
    bare = AgentFloorVectorEnv(n)
    remote = gym.make_vec("remoteenv/Reacher-v0", n, vectorization_mode="vector_entry_point")
    pids = list(bare._vector.pids)
    try:
        assert bare._vector.slices == remote.unwrapped.slices
        obs_b, _ = bare.reset(seed=3)
        obs_r, _ = remote.reset(seed=3)
        np.testing.assert_array_equal(obs_b, obs_r)
        assert assert_same_reacher_episodes(bare, remote, n) == 2
        # All but the first step (which attaches the regions) and the two resetting ones went the bare way.
        assert (bare.bare_steps, bare.full_steps) == (2 * 51 + 3 - 3, 3)
    finally:
        bare.close()
        remote.close()
    assert pids and all(wait_gone(pid) for pid in pids)


def test_the_two_ends_of_the_lane_are_reported_as_ratios():
    rows = [
        {"name": name, "num_envs": 16, "median": rate, "cpu_us_per_step": cpu}
        for name, rate, cpu in (
            ("remoteenv", 300.0, 50.0),
            ("agent-floor", 400.0, 40.0),
            ("process-floor", 600.0, 25.0),
        )
    ]
    found = {r["ratio"]: r["value"] for r in ratios(rows)}
    assert found["remoteenv / agent-floor, N=16"] == 0.75
    assert found["agent-floor / process-floor, N=16"] == 400.0 / 600.0
