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


def _make(num_envs: int = 4, **kwargs):
    return gym.make_vec(REACHER, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs).unwrapped


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
    # A real-time sim hosts one world: two worlds, two sims, as many as fit on two CPUs.
    for kwargs in (
        {"envs_per_process": 2, "place_sims": None},
        {"num_envs": 2, "envs_per_process": 1, "real_time": True},
    ):
        env = _make(**kwargs)
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


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="pinning needs two CPUs")
def test_a_pinned_sim_kept_off_its_cpu_by_a_busy_neighbour_takes_its_cpus_back_until_it_leaves():
    import subprocess
    import sys
    import time

    import numpy as np

    env = _make(envs_per_process=2)
    hog = None
    try:
        pids = env.pids
        first = os.sched_getaffinity(pids[0])
        assert len(first) == 1  # pinned, as above
        # A CPU hog on that CPU alone: the sim there waits for it, time slice after time slice.
        hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        os.sched_setaffinity(hog.pid, first)
        env.reset(seed=0)
        actions = np.zeros((4, 2), np.float32)
        deadline = time.monotonic() + 120.0  # generous: this loop ends as soon as the sim moved
        while os.sched_getaffinity(pids[0]) == first and time.monotonic() < deadline:
            for _ in range(32):
                env.step(actions)
        assert os.sched_getaffinity(pids[0]) == set(_cpus())
        assert env.pids == pids  # the same sims, still serving
        env.step(actions)
        hog.kill()  # the neighbour leaves: the sim tries its CPU again, RETRY_S later
        hog.wait()
        hog = None
        # (Whether it then keeps it depends on the rest of the machine: the unit tests cover that.)
        deadline = time.monotonic() + 120.0  # generous, as above
        while os.sched_getaffinity(pids[0]) != first and time.monotonic() < deadline:
            for _ in range(8):
                env.step(actions)
        assert os.sched_getaffinity(pids[0]) == first and env.pids == pids
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
        env.close()
