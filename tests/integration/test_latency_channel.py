"""Delivery rules, delayed rewards and the leak-free info end to end (sims in their own processes)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv import RemoteVectorEnv
from remoteenv.delays import Uniform
from remoteenv.latency.action_history import ActionHistory
from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.delay_line import LockStepDelays

#: Every key a delayed lock-step step adds to the scene's info (docs/delays.md's table).
DELAY_KEYS = {
    "action_delay_ticks",
    "applied_action",
    "action_took_effect",
    "obs_delay_ticks",
    "obs_sim_time",
    "obs_action_delay_ticks",
    "obs_applied_action",
    "latency_ticks",
    "latency_s",
    "late",
    "sim_time",
    "ticks_elapsed",
    "wall_round_trip_s",
}


def test_the_env_reports_exactly_the_engines_leak_free_values_and_the_history_appends_them():
    """The leak test runs on the engine (tests/unit/test_delay_leaks.py); here a real
    env's info, step by step, is the engine's, and ActionHistory's features are those keys."""
    seed, steps = 5, 400
    rules = ChannelRules(action_delivery="in_order", obs_delivery="newest")
    delays = {"action_delay": Uniform(0, 4), "obs_delay": Uniform(0, 3)}
    env = gym.make("remoteenv/Reacher-v0", max_episode_steps=steps + 1, action_delivery="in_order", **delays)
    wrapped = ActionHistory(env, 8, include_latency=True, include_alpha=True, include_obs_delay=True)
    engine = LockStepDelays(delays["action_delay"], delays["obs_delay"], rules)
    rng = np.random.default_rng(0)
    try:
        wrapped.reset(seed=seed)
        engine.reset(0, 0.0, None, seed=seed)
        scene_keys = None
        for t in range(1, steps + 1):
            action = rng.uniform(-1, 1, size=2).astype(np.float32)
            obs, _, terminated, truncated, info = wrapped.step(action)
            engine.apply(t)
            _, record = engine.observe(t, 0.0)
            expected = record.info()
            for key in ("action_delay_ticks", "obs_delay_ticks", "obs_action_delay_ticks", "latency_ticks"):
                assert info[key] == expected[key], f"step {t}: {key}"
            assert info["action_took_effect"] == expected["action_took_effect"]
            assert info["late"] == (expected["action_delay_ticks"] > 0)
            latency = expected["latency_ticks"]
            assert list(obs[-3:]) == [expected["obs_action_delay_ticks"], expected["obs_delay_ticks"], latency or 0]
            keys = set(info) - DELAY_KEYS
            scene_keys = keys if scene_keys is None else scene_keys
            assert keys == scene_keys  # nothing else appears: the scene's own keys and the documented ones
            assert not terminated and not truncated
    finally:
        wrapped.close()


def run_episode(env_id, seed, push, **kwargs):
    env = gym.make(env_id, continuous=True, max_episode_steps=None, **kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        total, n, out = 0.0, 0, [obs]
        while True:
            obs, reward, terminated, truncated, info = env.step(push)
            total += float(reward)
            n += 1
            out.append(obs)
            if terminated or truncated:
                return total, n, out, info, env.unwrapped.handshake
    finally:
        env.close()


def test_delayed_rewards_end_the_episode_when_the_terminal_observation_arrives():
    push = np.ones(1, dtype=np.float32)
    plain_total, plain_n, plain_obs, _, _ = run_episode("remoteenv/CartPole-v0", 2, push, action_delay=1)
    total, n, obs, info, hs = run_episode(
        "remoteenv/CartPole-v0", 2, push, action_delay=1, obs_delay=3, delayed_rewards=True
    )
    assert hs["stepping"]["channel"] == ChannelRules(delayed_rewards=True).to_wire()
    assert n == plain_n + 3  # the terminal observation is 3 ticks on its way
    assert total == plain_total  # every tick's reward arrives, with its observation
    np.testing.assert_array_equal(obs[-1], plain_obs[-1])  # the episode ends on the terminal observation
    # The physics froze at the terminal tick, 3 steps ago; sim_time ran on (the agent could not know).
    assert info["obs_delay_ticks"] == 3 and info["sim_time"] == pytest.approx(info["obs_sim_time"] + 3 * 0.02)
    assert info["sim_time"] == pytest.approx(n * 0.02)


def test_the_default_keeps_the_reward_and_end_of_the_tick_that_ran():
    push = np.ones(1, dtype=np.float32)
    plain_total, plain_n, _, _, _ = run_episode("remoteenv/CartPole-v0", 2, push, action_delay=1)
    total, n, _, _, hs = run_episode("remoteenv/CartPole-v0", 2, push, action_delay=1, obs_delay=3)
    assert (total, n) == (plain_total, plain_n) and "channel" not in hs["stepping"]


def test_a_vector_env_passes_the_rules_to_every_world():
    push = np.ones((2, 1), dtype=np.float32)
    lengths = {}
    for delayed in (False, True):
        env = RemoteVectorEnv(
            remoteenv.scene_path("cartpole"),
            num_envs=2,
            envs_per_process=2,
            continuous=True,
            action_delay=Uniform(0, 2),
            obs_delay=2,
            delayed_rewards=delayed,
            action_delivery="in_order",
        )
        try:
            env.reset(seed=4)
            returns, ended = np.zeros(2), [None, None]
            for step in range(1, 200):
                _, rewards, terminated, truncated, _ = env.step(push)
                for w in range(2):
                    if ended[w] is None:
                        returns[w] += rewards[w]
                        if terminated[w]:
                            ended[w] = step
                if all(e is not None for e in ended):
                    break
            stats = env.latency_stats
        finally:
            env.close()
        lengths[delayed] = (ended, returns.tolist())
        assert stats.actions_sent > 0 and stats.action_age_ticks.count == stats.actions_sent
    (plain_end, plain_ret), (delayed_end, delayed_ret) = lengths[False], lengths[True]
    assert delayed_ret == plain_ret
    assert delayed_end == [e + 2 for e in plain_end]


def test_rules_without_a_lock_step_delay_or_in_real_time_are_refused_or_moot():
    with pytest.raises(ValueError, match="lock-step"):
        gym.make("remoteenv/CartPole-v0", real_time=True, delayed_rewards=True)
    with pytest.raises(ValueError, match="action_delivery"):
        gym.make("remoteenv/CartPole-v0", action_delay=1, action_delivery="fifo")
