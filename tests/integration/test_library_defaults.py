"""Each library on remoteenv's defaults: Gymnasium's vector wrappers on the
default vector env, Stable-Baselines3 and TorchRL through their adapters, all
across episode ends (a 5-step time limit)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

ID = "remoteenv/CartPole-v0"


def test_gymnasium_vector_wrappers_take_the_default_vector_env():
    envs = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=5)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    envs = gym.wrappers.vector.RecordEpisodeStatistics(gym.wrappers.vector.NormalizeObservation(envs))
    try:
        envs.reset(seed=0)
        episodes = 0
        for _ in range(12):
            obs, reward, terminated, truncated, info = envs.step(np.zeros(2, dtype=np.int64))
            assert obs.shape == (2, 4) and np.isfinite(obs).all()
            episodes += int(info.get("_episode", np.zeros(2, bool)).sum())
        assert episodes >= 2
    finally:
        envs.close()


def test_sb3_on_the_default_and_through_its_adapter(tmp_path):
    sb3 = pytest.importorskip("stable_baselines3")
    from remoteenv.integrations.sb3 import SB3VecEnv, make_sb3_vec_env

    default = SB3VecEnv(gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=5))
    adapted = make_sb3_vec_env(ID, num_envs=2, max_episode_steps=5)
    try:
        assert default.autoreset_mode == AutoresetMode.NEXT_STEP
        assert adapted.autoreset_mode == AutoresetMode.SAME_STEP
        for venv in (default, adapted):
            model = sb3.PPO("MlpPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0)
            model.learn(64)  # tiny: that it runs, not what it learns
            model.save(tmp_path / "ppo")
            loaded = sb3.PPO.load(tmp_path / "ppo", env=venv)
            obs = venv.reset()
            actions, _ = loaded.predict(obs, deterministic=True)
            assert actions.shape == (2,)
    finally:
        default.close()
        adapted.close()


def test_torchrl_through_its_adapter():
    pytest.importorskip("torchrl")
    from torchrl.envs.utils import check_env_specs

    from remoteenv.integrations.torchrl import make_torchrl_env

    env = make_torchrl_env(ID, num_envs=2, max_episode_steps=5, seed=0)
    try:
        check_env_specs(env)
        rollout = env.rollout(12, break_when_any_done=False)
        assert tuple(rollout.batch_size) == (2, 12)
        done = rollout["next", "done"].squeeze(-1).numpy()
        assert done.sum() >= 4  # episodes ended and the rollout went on
        i, t = np.argwhere(done[:, :-1])[0]
        last = rollout["next", "observation"][i, t].numpy()
        first = rollout["observation"][i, t + 1].numpy()
        assert not np.array_equal(last, first)  # the next step starts a new episode
    finally:
        env.close()


def test_torchrl_gym_wrapper_refuses_the_default_and_says_why():
    torchrl_envs = pytest.importorskip("torchrl.envs")
    envs = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point")
    try:
        with pytest.raises(RuntimeError, match="SAME_STEP or DISABLED"):
            torchrl_envs.GymWrapper(envs)
    finally:
        envs.close()


@pytest.mark.parametrize("obs_mode", ["state_pixels", "pixels"])
def test_torchrl_camera_observations_roll_out_across_episode_ends(obs_mode):
    """A Dict observation (state and image) and an image alone through the
    adapter: the rollout goes on across episode ends (TorchRL's SAME_STEP path
    raised "generator raised StopIteration" at the first on a Dict), and the keys
    are those TorchRL's GymEnv gives: "pixels", and "observation" for the state."""
    pytest.importorskip("torchrl")
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    from remoteenv.torchrl import make_torchrl_env

    env = make_torchrl_env(ID, num_envs=2, max_episode_steps=5, seed=0, obs_mode=obs_mode, image_size=24)
    single = GymEnv(ID, obs_mode=obs_mode, image_size=24)
    try:
        check_env_specs(env)
        assert set(env.observation_spec.keys()) == set(single.observation_spec.keys())
        rollout = env.rollout(12, break_when_any_done=False)
        assert tuple(rollout.batch_size) == (2, 12)
        assert rollout["next", "pixels"].shape == (2, 12, 24, 24, 3)
        done = rollout["next", "done"].squeeze(-1).numpy()
        assert done.sum() >= 4  # episodes ended and the rollout went on
        if obs_mode == "state_pixels":
            i, t = np.argwhere(done[:, :-1])[0]
            last, first = rollout["next", "observation"][i, t].numpy(), rollout["observation"][i, t + 1].numpy()
            assert not np.array_equal(last, first)  # the next step starts a new episode
    finally:
        env.close()
        single.close()
