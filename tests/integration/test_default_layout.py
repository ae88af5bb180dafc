"""The default layout of a vector env follows what one world's whole tick costs:
physics and every hook, however the scene spends it. A scene that renders its
image observation in its own hook (no camera declared) is laid out like one
with a declared camera; cheap worlds keep theirs; where the cost cannot change
the layout nothing is measured. These tests assert the layout chosen, never a
speed."""

from __future__ import annotations

import gymnasium as gym

from remoteenv import RemoteVectorEnv
from remoteenv.agent.vector.vector_layout import COSTLY_WORLD_S, default_envs_per_process
from remoteenv.benchmarks.pixels import HOOK_RENDER_SCENE as HOOK_RENDER


def test_a_scene_that_renders_in_its_hook_is_laid_out_as_a_costly_world():
    env = RemoteVectorEnv(HOOK_RENDER, num_envs=8)
    try:
        assert env.world_cost_s is not None and env.world_cost_s > COSTLY_WORLD_S  # the hook's render counted
        assert env.envs_per_process == default_envs_per_process(8, float("inf"))  # one process per CPU
        assert len(env.pids) == len(env.slices) == -(-8 // env.envs_per_process)
        obs, _ = env.reset(seed=0)
        assert obs.shape == (8, 64, 64, 3)
        obs, reward, *_ = env.step(env.action_space.sample())
        assert obs.shape == (8, 64, 64, 3) and list(reward) == [1.0] * 8
    finally:
        env.close()


def test_cheap_worlds_keep_their_layout_and_are_measured_only_where_it_matters():
    env = gym.make_vec("remoteenv/Reacher-v0", num_envs=8, vectorization_mode="vector_entry_point").unwrapped
    try:
        assert env.world_cost_s is not None and env.world_cost_s <= COSTLY_WORLD_S
        assert env.envs_per_process == default_envs_per_process(8, None)
    finally:
        env.close()
    env = gym.make_vec("remoteenv/Reacher-v0", num_envs=64, vectorization_mode="vector_entry_point").unwrapped
    try:
        assert env.world_cost_s is None  # both rules give the same K: nothing to measure
        assert env.envs_per_process == default_envs_per_process(64, None)
    finally:
        env.close()


def test_an_explicit_layout_is_kept_and_not_measured():
    env = RemoteVectorEnv(HOOK_RENDER, num_envs=4, envs_per_process=4)
    try:
        assert env.envs_per_process == 4 and env.world_cost_s is None and len(env.pids) == 1
    finally:
        env.close()
