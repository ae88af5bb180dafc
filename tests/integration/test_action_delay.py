"""action_delay=k (lock-step): the action sent at step t takes effect at tick t + k.

Checked against an in-process run of the same scene that applies the
scene's default action for the first k ticks and then the actions k ticks
late; the observations must be bit-identical.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.scenes.reacher.reacher_scene import ReacherEnv


def run_remote(env_id: str, delay: int, seed: int, actions: list, **kwargs):
    env = gym.make(env_id, action_delay=delay, **kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        out = [(obs, 0.0, {})]
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(a)
            out.append((obs, reward, info))
            assert not truncated
            if terminated:
                break
        return out, env.unwrapped.latency_stats.summary()
    finally:
        env.close()


def run_local(env: CartPoleEnv | ReacherEnv, delay: int, seed: int, actions: list):
    """What action_delay=delay must do: None (the default action) for k ticks, then a[t - k]."""
    obs, _ = env.reset(seed=seed)
    out = [obs]
    applied = [env.default_action()] * delay + list(actions)
    for t in range(len(actions)):
        obs, _, terminated, _ = env.step(applied[t])
        out.append(obs)
        if terminated:
            break
    return out, applied


@pytest.mark.parametrize("delay", [1, 3])
def test_reacher_first_k_steps_use_the_default_then_actions_arrive_k_late(delay):
    rng = np.random.default_rng(1)
    actions = [rng.uniform(-1, 1, size=2).astype(np.float32) for _ in range(12)]
    remote, stats = run_remote("remoteenv/Reacher-v0", delay, 5, actions)
    local, applied = run_local(ReacherEnv(), delay, 5, actions)
    assert len(remote) == len(local) == len(actions) + 1
    for t, ((obs, _, info), expected) in enumerate(zip(remote, local)):
        np.testing.assert_array_equal(obs, expected)
        if t == 0:
            continue
        if t <= delay:  # step t ran tick t - 1 with the default (zero) action
            assert info["applied_action"] is None
        else:
            np.testing.assert_array_equal(info["applied_action"], applied[t - 1])
            np.testing.assert_array_equal(info["applied_action"], actions[t - 1 - delay])
        assert info["action_delay_ticks"] == min(t, delay) and info["ticks_elapsed"] == 1
        if t <= delay:  # the default acts: its latency is not a thing yet
            assert info["latency_ticks"] is None and info["latency_s"] is None
        else:  # after the fact: the action in force arrived delay ticks after the observation it answered
            assert info["latency_ticks"] == delay and info["latency_s"] == pytest.approx(delay * 0.02)
        assert info["sim_time"] == pytest.approx(t * 0.02)
    assert stats["latency_ticks"]["max"] == delay and stats["late_actions"] == len(actions)
    # the run's stats: the action in force is delay ticks old once the default is gone;
    # the last delay actions were still on their way when the run stopped
    assert stats["action_age_ticks"]["max"] == delay and stats["actions_sent"] == len(actions)
    assert stats["never_acted_fraction"] == pytest.approx(delay / len(actions))
    # The delay changes the trajectory: the zero-delay run differs after tick 1.
    undelayed, _ = run_local(ReacherEnv(), 0, 5, actions)
    assert not np.array_equal(undelayed[2], local[2])


def test_cartpole_discrete_default_is_zero_force_for_the_first_k_ticks():
    actions = [1, 1, 0, 1, 0, 0, 1, 1]
    delay = 2
    remote, _ = run_remote("remoteenv/CartPole-v0", delay, 0, actions)
    local, _ = run_local(CartPoleEnv(), delay, 0, actions)
    for (obs, _reward, _), expected in zip(remote, local):
        np.testing.assert_array_equal(obs, expected)
    # With zero force for two ticks the cart velocity barely moves; a +10 N push would.
    assert abs(remote[2][0][1] - remote[0][0][1]) < 0.01
    assert remote[3][0][1] - remote[2][0][1] > 0.1


def test_same_seed_and_actions_give_the_same_trajectory_in_separate_processes():
    rng = np.random.default_rng(2)
    actions = [rng.uniform(-1, 1, size=(1,)).astype(np.float32) for _ in range(30)]
    a, _ = run_remote("remoteenv/CartPole-v0", 4, 11, actions, continuous=True)
    b, _ = run_remote("remoteenv/CartPole-v0", 4, 11, actions, continuous=True)
    c, _ = run_remote("remoteenv/CartPole-v0", 4, 12, actions, continuous=True)
    assert len(a) == len(b)
    for (obs_a, rew_a, _), (obs_b, rew_b, _) in zip(a, b):
        np.testing.assert_array_equal(obs_a, obs_b)
        assert rew_a == rew_b
    assert not np.array_equal(a[1][0], c[1][0])


def test_reset_refills_the_queue_with_the_default_action():
    env = gym.make("remoteenv/Reacher-v0", action_delay=2)
    try:
        push = np.ones(2, dtype=np.float32)
        env.reset(seed=0)
        for _ in range(4):
            env.step(push)
        env.reset(seed=0)
        infos = [env.step(push)[4] for _ in range(3)]
        assert infos[0]["applied_action"] is None and infos[1]["applied_action"] is None
        np.testing.assert_array_equal(infos[2]["applied_action"], push)
    finally:
        env.close()


def test_negative_delay_is_refused():
    from remoteenv.sim.stepping.lock_step import LockStepper
    from remoteenv.wire.run_options.options import RunOptions

    with pytest.raises(ValueError, match="action_delay"):
        LockStepper(ReacherEnv(), RunOptions(action_delay=-1))
