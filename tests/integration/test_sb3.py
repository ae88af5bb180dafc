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

    from remoteenv.sb3 import SB3VecEnv

    venv = SB3VecEnv(_sync_venv(2, AutoresetMode(mode), max_episode_steps=30))
    try:
        venv.action_space.seed(0)
        _check_sb3_done_semantics(venv, 30)
    finally:
        venv.close()


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_adapter_done_semantics_over_remote_vector_env(mode):
    from remoteenv.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env("remoteenv/CartPole-v0", num_envs=3, autoreset_mode=mode, max_episode_steps=30, seed=0)
    try:
        venv.action_space.seed(1)
        _check_sb3_done_semantics(venv, 30)
    finally:
        venv.close()


def test_sb3_ppo_learns_on_the_remote_vector_env():
    from stable_baselines3 import PPO

    import remoteenv
    from remoteenv.sb3 import SB3VecEnv
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
