"""RLlib PPO (new API stack) trains on a plain remoteenv id: two iterations of the
example, and one of each vectorize mode after remoteenv.integrations.rllib.register_envs()."""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys

import pytest

pytest.importorskip("ray.rllib")

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "train_rllib_cartpole.py")


def _example():
    spec = importlib.util.spec_from_file_location("train_rllib_cartpole", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_RUNNER = """
import sys
import gymnasium as gym
assert "remoteenv" not in sys.modules
try:
    gym.make_vec("remoteenv/CartPole-v0", num_envs=2, vectorization_mode="vector_entry_point")
except gym.error.NamespaceNotFound:
    print("plain id: NamespaceNotFound")
envs = gym.make_vec("remoteenv:remoteenv/CartPole-v0", num_envs=2, vectorization_mode="vector_entry_point")
print("prefixed id:", type(envs).__name__, envs.reset(seed=0)[0].shape, gym.__version__)
envs.close()
"""


def test_the_module_prefixed_id_works_where_remoteenv_was_never_imported() -> None:
    # What an RLlib env runner does: gym.make_vec on the configured id in a
    # fresh process that never imported remoteenv.
    out = subprocess.run([sys.executable, "-c", _RUNNER], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert lines[0] == "plain id: NamespaceNotFound"
    assert lines[1].startswith("prefixed id: RemoteVectorEnv (2, 4) 1.2.")


def test_ppo_trains_two_iterations_on_remote_cartpole(cluster) -> None:
    rows = _example().train(iterations=2, target=math.inf, env_runners=1, envs_per_runner=2)
    assert [r["iteration"] for r in rows] == [1, 2]
    assert all(r["return_mean"] > 0 for r in rows)
    assert rows[-1]["env_steps"] >= 2 * 4000


@pytest.mark.parametrize("vectorize", ["vector_entry_point", "sync"])
def test_the_plain_id_trains_after_one_call_in_the_driver(cluster, vectorize) -> None:
    from ray.rllib.algorithms.ppo import PPOConfig

    import remoteenv.integrations.rllib

    assert "remoteenv/CartPole-v0" in remoteenv.integrations.rllib.register_envs()
    config = (
        PPOConfig()
        .environment("remoteenv/CartPole-v0", env_config={"seed": 0, "continuous": True})
        .env_runners(num_env_runners=1, num_envs_per_env_runner=2, gym_env_vectorize_mode=vectorize)
        .training(train_batch_size_per_learner=128, minibatch_size=64, num_epochs=1)
    )
    algo = config.build_algo()  # the runners build their envs here
    try:
        result = algo.train()  # tiny: that it samples and learns, not what it learns
        assert result["env_runners"]["num_env_steps_sampled"] >= 128
        built = algo.env_runner_group.foreach_env_runner(
            lambda r: (type(r.env.unwrapped).__name__, r.num_envs), local_env_runner=False
        )
        assert built == [("RemoteVectorEnv" if vectorize == "vector_entry_point" else "SyncVectorEnv", 2)]
    finally:
        algo.stop()


def _one_iteration(env_config: dict, vectorize: str = "vector_entry_point", connector=None) -> tuple[dict, list]:
    """One tiny PPO iteration on CartPole with ``env_config``: the result, and
    each runner's env observation space."""
    from ray.rllib.algorithms.ppo import PPOConfig

    import remoteenv.rllib

    remoteenv.rllib.register_envs()
    config = (
        PPOConfig()
        .environment("remoteenv/CartPole-v0", env_config={"seed": 0, **env_config})
        .env_runners(
            num_env_runners=1,
            num_envs_per_env_runner=2,
            gym_env_vectorize_mode=vectorize,
            env_to_module_connector=connector,
        )
        .training(train_batch_size_per_learner=64, minibatch_size=32, num_epochs=1)
    )
    algo = config.build_algo()
    try:
        result = algo.train()  # tiny: that it samples and learns, not what it learns
        spaces = algo.env_runner_group.foreach_env_runner(
            lambda r: r.env.single_observation_space, local_env_runner=False
        )
        return result, spaces
    finally:
        algo.stop()


@pytest.mark.parametrize("vectorize", ["vector_entry_point", "sync"])
def test_ppo_samples_and_trains_on_camera_images(cluster, vectorize) -> None:
    """RLlib's default CNN takes float images: the runners get the uint8 camera
    images scaled to float32 in [0, 1] (64x64: a size with a default CNN)."""
    import numpy as np

    result, spaces = _one_iteration({"obs_mode": "pixels", "image_size": 64}, vectorize)
    assert result["env_runners"]["num_env_steps_sampled"] >= 64
    assert result["learners"]["default_policy"]["num_module_steps_trained"] > 0
    (space,) = spaces
    assert space.shape == (64, 64, 3) and space.dtype == np.float32 and space.high.max() == 1.0


def test_a_dict_observation_trains_with_rllibs_flatten_connector(cluster) -> None:
    """RLlib's default models take one Box: a Dict (state beside the image)
    trains once RLlib's own FlattenObservations connector flattens it."""
    from ray.rllib.connectors.env_to_module import FlattenObservations

    result, _ = _one_iteration(
        {"obs_mode": "state_pixels", "image_size": 16},
        connector=lambda env, spaces, device: FlattenObservations(),
    )
    assert result["env_runners"]["num_env_steps_sampled"] >= 64
