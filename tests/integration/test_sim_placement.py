"""A vector env's own lock-step sims run as batch work, pinned one to a CPU
when they fit (remoteenv.agent.vector.sim_placement); real-time sims, sims of
a user's launcher and ``place_sims=None`` are left to the OS scheduler; a
relaunched sim is placed again at the next reset. These tests assert the
placement, never a speed."""

from __future__ import annotations

import os

import gymnasium as gym
import pytest

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs Linux scheduling calls")

REACHER = "remoteenv/Reacher-v0"


def _make(**kwargs):
    return gym.make_vec(REACHER, num_envs=4, vectorization_mode="vector_entry_point", **kwargs).unwrapped


def _cpus() -> list[int]:
    return sorted(os.sched_getaffinity(0))


def test_own_lock_step_sims_are_batch_work_on_a_cpu_each():
    env = _make(envs_per_process=2)
    try:
        pids = env.pids
        assert len(pids) == 2
        for pid in pids:
            assert os.sched_getscheduler(pid) == os.SCHED_BATCH
        if len(_cpus()) >= 2:
            assert [os.sched_getaffinity(pid) for pid in pids] == [{_cpus()[0]}, {_cpus()[1]}]
        assert os.sched_getaffinity(0) == set(_cpus())  # the user's process is untouched
        assert os.sched_getscheduler(0) == os.SCHED_OTHER
        env.reset(seed=0)
        env.step(env.action_space.sample())
    finally:
        env.close()


def test_place_sims_none_and_real_time_leave_the_sims_to_the_os():
    for kwargs in ({"place_sims": None}, {"real_time": True}):
        env = _make(envs_per_process=2, **kwargs)
        try:
            for pid in env.pids:
                assert os.sched_getscheduler(pid) == os.SCHED_OTHER, kwargs
                assert os.sched_getaffinity(pid) == set(_cpus()), kwargs
        finally:
            env.close()


def test_a_relaunched_sim_is_placed_again_at_the_next_reset():
    env = _make(envs_per_process=2, restart_on_failure=True)
    try:
        env.reset(seed=0)
        old = env.pids
        os.kill(old[1], 9)
        _, _, _, _, info = env.step(env.action_space.sample())
        assert info["_remoteenv_restarted"].tolist() == [False, False, True, True]
        env.reset(seed=1)
        new = env.pids
        assert new[1] != old[1]
        assert os.sched_getscheduler(new[1]) == os.SCHED_BATCH
    finally:
        env.close()
