"""rtgym's regime, real_time_mode="fixed_step", in a real sim process.

Timing is the behaviour here. The relations the regime guarantees whatever
the timing are asserted exactly: each action takes effect at a control-tick
boundary, the one where its step ends, so its latency is a whole number of
ticks equal to the ticks the step lasted, and the reward sums those ticks.
How often an agent that thinks a third of a tick makes it within one tick
is up to the scheduler: that bound is generous (a loaded 2-core host may
stall a process for tens of milliseconds) and says so.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

import remoteenv
from remoteenv import RemoteVectorEnv
from remoteenv.controllers import cartpole_continuous

ENV_ID = "remoteenv/CartPole-v0"


def test_an_agent_thinking_a_third_of_a_tick_gets_one_tick_per_step_with_a_latency_of_one_tick():
    env = gym.make(ENV_ID, continuous=True, real_time=True, real_time_mode="fixed_step", max_episode_steps=60)
    try:
        assert env.unwrapped.handshake.real_time_mode == "fixed_step"
        tick_s = env.unwrapped.dt
        frame_skip = env.unwrapped.handshake.frame_skip
        obs, _ = env.reset(seed=1)
        infos = []
        last_substep = 0
        done = False
        while not done:
            action = cartpole_continuous(obs)
            time.sleep(tick_s / 3)
            obs, reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            infos.append(info)
            # Exact, whatever the timing: the step ends at the boundary where its action took effect.
            assert info["action_substep"] == info["substep"] == last_substep + info["ticks_elapsed"] * frame_skip
            assert info["latency_ticks"] == info["ticks_elapsed"] >= 1
            assert reward == float(info["ticks_elapsed"])  # CartPole: +1 per tick
            assert info["late"] == (info["ticks_elapsed"] > 1)
            last_substep = info["substep"]
    finally:
        env.close()
    assert len(infos) == 60 and not terminated
    on_time = sum(i["ticks_elapsed"] == 1 for i in infos)
    # Generous bound (load): a third of a tick plus a round trip fits in a tick for most steps.
    assert on_time >= 0.7 * len(infos), [i["ticks_elapsed"] for i in infos]


def test_the_regime_reaches_every_world_of_a_vector_env_and_is_refused_in_lock_step():
    envs = RemoteVectorEnv(
        remoteenv.scene_path("cartpole"), 2, real_time=True, real_time_mode="fixed_step", continuous=True
    )
    try:
        frame_skip = envs.handshake.frame_skip
        envs.reset(seed=0)
        _, _, _, _, infos = envs.step(np.zeros((2, 1), np.float32))
        assert list(infos["latency_ticks"]) == list(infos["ticks_elapsed"].astype(float))
        assert all(s > 0 and s % frame_skip == 0 for s in infos["action_substep"])  # tick boundaries
    finally:
        envs.close()
    try:
        gym.make(ENV_ID, real_time_mode="fixed_step")
    except ValueError as exc:
        assert "real_time=True" in str(exc)
    else:
        raise AssertionError("fixed_step without real_time was accepted")
