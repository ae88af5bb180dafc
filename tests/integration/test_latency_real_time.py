"""Real time: pause/resume and the emulated link, in a real sim process.

Timing is the behaviour here. Where a bound on wall time is unavoidable it
is generous (a loaded 2-core host may stall a process for tens of
milliseconds) and says so; the exact parts (sim time does not move while
paused) are asserted exactly.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv import RemoteVectorEnv
from remoteenv.delays import Constant, Uniform

PUSH = np.zeros(1, dtype=np.float32)


def test_pause_freezes_sim_time_and_counts_in_no_latency_figure():
    env = gym.make("remoteenv/CartPole-v0", continuous=True, real_time=True)
    try:
        env.reset(seed=0)
        env.step(PUSH)
        (at_pause,) = env.unwrapped.pause()
        assert env.unwrapped.is_paused
        time.sleep(0.5)
        timing = env.unwrapped._request("timing")["worlds"][0]
        # Exact: no substep ran while paused.
        assert env.unwrapped.pause() == [at_pause]  # pausing again changes nothing
        paused_s = env.unwrapped.resume()
        assert not env.unwrapped.is_paused
        # Generous bound (load): the sim measured the 0.5 s sleep, give or take 0.3 s.
        assert 0.5 <= paused_s < 0.8
        _, _, _, _, info = env.step(PUSH)
        after = env.unwrapped._request("timing")["worlds"][0]
    finally:
        env.close()
    # The step right after the resume sees well under the 0.5 s paused: at most a
    # few ticks ran between pause and this step's reply (generous: 0.25 s sim).
    assert info["sim_time"] - at_pause < 0.25
    assert info["latency_s"] < 0.25
    # No substep was counted late because of the pause. Had the pause leaked
    # into the deadlines, every substep of the 0.5 s (250 of 2 ms) would have
    # run late at once; a loaded host may still make a few of the substeps
    # after the resume late on its own (seen: 1 at load 6), so the bound is a
    # tenth of what a leak would count (timing is the behaviour here).
    leaked = 0.5 / 0.002  # CartPole's physics timestep is 2 ms
    assert after["overruns"] - timing["overruns"] < leaked / 10


def test_the_context_manager_resumes_even_on_error_and_lock_step_is_a_no_op():
    env = gym.make("remoteenv/CartPole-v0", continuous=True, real_time=True)
    lock = gym.make("remoteenv/CartPole-v0")
    try:
        env.reset(seed=0)
        with pytest.raises(RuntimeError), env.unwrapped.paused():
            assert env.unwrapped.is_paused
            raise RuntimeError("the learner's update failed")
        assert not env.unwrapped.is_paused
        lock.reset(seed=0)
        assert lock.unwrapped.pause() == [] and lock.unwrapped.resume() == 0.0
        with lock.unwrapped.paused():
            lock.step(0)
    finally:
        env.close()
        lock.close()


def test_vector_env_pauses_every_sim():
    env = RemoteVectorEnv(remoteenv.scene_path("cartpole"), num_envs=2, real_time=True, continuous=True)
    try:
        env.reset(seed=1)
        times = env.pause()
        assert len(times) == 2
        time.sleep(0.2)
        assert env.pause() == times  # exact: both clocks stood still
        assert env.resume() >= 0.2
    finally:
        env.close()


def test_an_emulated_link_delays_every_action_by_its_draw():
    env = gym.make("remoteenv/CartPole-v0", continuous=True, real_time=True, link_delay=Constant(0.03, unit="s"))
    try:
        env.reset(seed=2)
        infos = [env.step(PUSH)[4] for _ in range(5)]
        timing = env.unwrapped._request("timing")["worlds"][0]
    finally:
        env.close()
    for info in infos:
        assert info["link_delay_s"] == 0.03
        assert info["apply_delay_s"] >= 0.03  # held back at least as long as the link says
        assert info["wall_round_trip_s"] >= 0.03
    assert timing["link_delay_s"]["count"] == 5 and timing["link_delay_s"]["max"] == 0.03


def test_link_jitter_repeats_with_the_seed():
    def drawn(seed):
        env = gym.make("remoteenv/CartPole-v0", continuous=True, real_time=True, link_delay=Uniform(0, 0.01, unit="s"))
        try:
            env.reset(seed=seed)
            return [env.step(PUSH)[4]["link_delay_s"] for _ in range(4)]
        finally:
            env.close()

    a, b = drawn(4), drawn(4)
    assert a == b and len(set(a)) == 4


def test_delays_are_refused_in_the_wrong_mode():
    with pytest.raises(ValueError, match="obs_delay"):
        gym.make("remoteenv/CartPole-v0", real_time=True, obs_delay=2)
    with pytest.raises(ValueError, match="link_delay"):
        gym.make("remoteenv/CartPole-v0", link_delay=0.01)
