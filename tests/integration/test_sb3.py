"""Stable-Baselines3: its env checker on both scenes, and PPO on the VecEnv adapter."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
from stable_baselines3.common.env_checker import check_env


@pytest.mark.parametrize("env_id", ["remoteenv/CartPole-v0", "remoteenv/Reacher-v0"])
def test_sb3_check_env_passes(env_id):
    env = gym.make(env_id)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # any checker warning fails the test
            check_env(env, warn=True, skip_render_check=True)
        obs, _ = env.reset(seed=0)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        # Reacher's reward is np.float64 as in Reacher-v5 (issue 14); SB3 needs a float.
        assert isinstance(reward, float)
        assert type(terminated) is bool and type(truncated) is bool
        assert isinstance(obs, np.ndarray) and obs.dtype == env.observation_space.dtype
    finally:
        env.close()


def _sync_venv(num_envs, autoreset_mode, max_episode_steps=500):
    return gym.make_vec(
        "remoteenv/CartPole-v0",
        num_envs=num_envs,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": autoreset_mode},
        max_episode_steps=max_episode_steps,
    )


def _check_sb3_done_semantics(venv, max_episode_steps):
    """Drive ``venv`` (an SB3VecEnv of CartPole) and check every done step."""
    venv.seed(0)
    obs = venv.reset()
    n = venv.num_envs
    lengths = np.zeros(n, dtype=int)
    terminations = truncations = 0
    for _ in range(3 * max_episode_steps):
        actions = np.array([venv.action_space.sample() for _ in range(n)])
        obs, rewards, dones, infos = venv.step(actions)
        assert rewards.dtype == np.float32 and dones.dtype == bool and len(infos) == n
        lengths += 1
        for i in range(n):
            if not dones[i]:
                assert "terminal_observation" not in infos[i]
                assert infos[i]["TimeLimit.truncated"] is False
                continue
            final = infos[i]["terminal_observation"]
            fell = abs(final[0]) > 2.4 or abs(final[2]) > 0.2094
            if infos[i]["TimeLimit.truncated"]:
                truncations += 1
                assert lengths[i] == max_episode_steps and not fell
            else:
                terminations += 1
                assert fell
            assert not np.array_equal(final, obs[i])
            assert np.all(np.abs(obs[i]) <= 0.05), "obs after done must start the next episode"
            lengths[i] = 0
    assert terminations > 0 and truncations > 0


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_adapter_done_semantics_over_sync_vector_env(mode):
    from gymnasium.vector import AutoresetMode

    from remoteenv.integrations.sb3 import SB3VecEnv

    venv = SB3VecEnv(_sync_venv(2, AutoresetMode(mode), max_episode_steps=30))
    try:
        venv.action_space.seed(0)
        _check_sb3_done_semantics(venv, 30)
    finally:
        venv.close()


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_adapter_done_semantics_over_remote_vector_env(mode):
    from remoteenv.integrations.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env("remoteenv/CartPole-v0", num_envs=3, autoreset_mode=mode, max_episode_steps=30, seed=0)
    try:
        venv.action_space.seed(1)
        _check_sb3_done_semantics(venv, 30)
    finally:
        venv.close()


def test_sb3_ppo_learns_on_the_remote_vector_env():
    from stable_baselines3 import PPO

    import remoteenv
    from remoteenv.integrations.sb3 import SB3VecEnv
    from remoteenv.vector_env import RemoteVectorEnv

    venv = SB3VecEnv(RemoteVectorEnv(remoteenv.scene_path("cartpole"), 4, max_episode_steps=500, seed=0))
    try:
        assert venv.num_envs == 4 and venv.render_mode is None
        model = PPO("MlpPolicy", venv, n_steps=256, batch_size=256, n_epochs=2, seed=0, device="cpu")
        model.learn(2048)
        assert model.num_timesteps >= 2048
        actions, _ = model.predict(venv.reset(), deterministic=True)
        assert actions.shape == (4,)
    finally:
        venv.close()


def _trajectory(venv, actions):
    """Every step's SB3 view of ``venv`` (reset with seed 0) under ``actions``."""
    try:
        venv.seed(0)
        steps = [(venv.reset(), None, None, None)]
        for a in actions:
            obs, rewards, dones, infos = venv.step(a)
            finals = [(info.get("terminal_observation"), info["TimeLimit.truncated"]) for info in infos]
            steps.append((obs, rewards, dones, finals))
        return steps
    finally:
        venv.close()


def _assert_same_trajectories(a, b):
    dones = truncations = 0
    for (obs_a, rew_a, done_a, fin_a), (obs_b, rew_b, done_b, fin_b) in zip(a, b, strict=True):
        np.testing.assert_array_equal(obs_a, obs_b)
        if rew_a is None:
            continue
        np.testing.assert_array_equal(rew_a, rew_b)
        np.testing.assert_array_equal(done_a, done_b)
        for (final_a, trunc_a), (final_b, trunc_b) in zip(fin_a, fin_b, strict=True):
            assert trunc_a == trunc_b
            assert (final_a is None) == (final_b is None)
            if final_a is not None:
                np.testing.assert_array_equal(final_a, final_b)
        dones += int(done_a.sum())
        truncations += sum(trunc for _, trunc in fin_a)
    assert dones > truncations > 0, "the trajectories must hold terminations and truncations"


@pytest.mark.parametrize("vectorization", ["sync", "remote"])
def test_adapter_gives_sb3_the_same_steps_for_same_step_and_next_step(vectorization):
    from gymnasium.vector import AutoresetMode

    from remoteenv.integrations.sb3 import SB3VecEnv, make_sb3_vec_env

    rng = np.random.default_rng(3)
    actions = [rng.integers(0, 2, size=3) for _ in range(120)]

    def build(mode):
        if vectorization == "sync":
            return SB3VecEnv(_sync_venv(3, mode, max_episode_steps=30))
        return make_sb3_vec_env("remoteenv/CartPole-v0", num_envs=3, autoreset_mode=mode, max_episode_steps=30)

    same = _trajectory(build(AutoresetMode.SAME_STEP), actions)
    nxt = _trajectory(build(AutoresetMode.NEXT_STEP), actions)
    _assert_same_trajectories(same, nxt)


@pytest.mark.parametrize("env_id", ["remoteenv/CartPole-v0", "remoteenv:remoteenv/CartPole-v0"])
def test_make_sb3_vec_env_builds_a_same_step_vector_env_unless_told_otherwise(env_id):
    from gymnasium.vector import AutoresetMode

    from remoteenv.integrations.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(env_id, num_envs=2)
    try:
        assert venv.autoreset_mode == AutoresetMode.SAME_STEP
        assert venv.venv.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    finally:
        venv.close()
    venv = make_sb3_vec_env("remoteenv/CartPole-v0", num_envs=2, autoreset_mode="NextStep")
    try:
        assert venv.autoreset_mode == AutoresetMode.NEXT_STEP
    finally:
        venv.close()
