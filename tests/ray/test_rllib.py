"""RLlib PPO (new API stack) trains on a remoteenv id: two iterations of the example."""

from __future__ import annotations

import importlib.util
import math
import os

import gymnasium as gym
import pytest

pytest.importorskip("ray.rllib")

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "train_rllib_cartpole.py")


def _example():
    spec = importlib.util.spec_from_file_location("train_rllib_cartpole", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_module_prefixed_id_needs_no_import_of_remoteenv() -> None:
    # What an RLlib env runner does: gym.make_vec on the id, in a process that
    # never imported remoteenv. Gymnasium imports the module before the colon.
    assert gym.__version__.startswith("1.2")
    envs = gym.make_vec("remoteenv:remoteenv/CartPole-v0", num_envs=2, vectorization_mode="vector_entry_point")
    try:
        obs, _ = envs.reset(seed=0)
        assert obs.shape == (2, 4)
    finally:
        envs.close()


def test_ppo_trains_two_iterations_on_remote_cartpole(cluster) -> None:
    rows = _example().train(iterations=2, target=math.inf, env_runners=1, envs_per_runner=2)
    assert [r["iteration"] for r in rows] == [1, 2]
    assert all(r["return_mean"] > 0 for r in rows)
    assert rows[-1]["env_steps"] >= 2 * 4000
