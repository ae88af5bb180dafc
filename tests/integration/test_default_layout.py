"""The default layout of a vector env follows what one world's whole tick costs:
physics and every hook, however the scene spends it. A scene that renders its
image observation in its own hook (no camera declared) is laid out like one
with a declared camera; cheap worlds keep theirs: one process stepping its
physics on threads where they are worth two threads and step as one batch, a
process per CPU where the scene's Python runs per world; where the cost cannot
change the layout nothing is measured. These tests assert the layout chosen,
never a speed."""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np

from remoteenv import RemoteVectorEnv
from remoteenv.agent.vector.vector_layout import (
    COSTLY_WORLD_S,
    cost_may_change_layout,
    default_envs_per_process,
    default_physics_threads,
)
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
    n = next(n for n in (15, 12, 1) if not cost_may_change_layout(n))
    env = gym.make_vec("remoteenv/Reacher-v0", num_envs=n, vectorization_mode="vector_entry_point").unwrapped
    try:
        assert env.world_cost_s is None  # both rules give the same K: nothing to measure
        assert env.envs_per_process == default_envs_per_process(n, None)
    finally:
        env.close()


def test_cheap_worlds_stepped_as_one_batch_run_in_one_process_on_threads():
    threads = default_physics_threads(16)
    env = gym.make_vec("remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point").unwrapped
    try:
        assert env.world_cost_s is not None and env.world_cost_s <= COSTLY_WORLD_S
        assert env.envs_per_process == default_envs_per_process(16, env.world_cost_s)
        if threads > 1:  # two CPUs or more: one process of 16 worlds, its physics on the threads
            assert env.envs_per_process == 16 and len(env.pids) == 1
        assert env.physics_threads == threads
        assert [hs.physics_threads for hs in env._session.handshakes] == [threads] * len(env.pids)
        assert all(hs.stacked_hooks for hs in env._session.handshakes)
        env.reset(seed=0)
        obs, reward, *_ = env.step(np.zeros((16, 2), np.float32))
        assert obs.shape == (16, 10) and reward.shape == (16,)
    finally:
        env.close()


def test_a_scene_whose_python_runs_per_world_keeps_a_process_per_cpu():
    scene = os.path.join(os.path.dirname(__file__), "scenes", "per_world_scene.py")
    env = RemoteVectorEnv(scene, num_envs=16)
    try:
        assert all(hs.stacked_hooks is False for hs in env._session.handshakes)
        assert env.envs_per_process == default_envs_per_process(16, env.world_cost_s, stacked_hooks=False)
        assert env.physics_threads == 1 and len(env.pids) == len(env.slices)
        env.reset(seed=0)
        env.step(np.ones(16, dtype=np.int64))
    finally:
        env.close()


def test_a_scene_that_cannot_pass_the_gate_is_probed_then_started_once(opened_sessions):
    """Worlds with lock-step delays step one by one, as a scratch world at the
    layout gate would not show (test_layout_gate.py has the gate): a probe of
    one world asks first, and they start once, in the layout it gives."""
    env = gym.make_vec(
        "remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point", action_delay=1
    ).unwrapped
    try:
        opened = [(o.processes, o.worlds_each, o.measured, o.probe) for o in opened_sessions]
        k = env.envs_per_process
        assert all(hs.stacked_hooks is False for hs in env._session.handshakes)
        assert k == default_envs_per_process(16, env.world_cost_s, stacked_hooks=False)
        if cost_may_change_layout(16):
            # one sim of one world measured, then the worlds in their layout, unmeasured: never a relaunch
            assert opened == [(1, 1, True, True), (len(env.slices), k, False, False)]
            assert env.world_cost_s is not None
        else:  # one CPU: nothing to measure, no probe
            assert opened == [(len(env.slices), k, False, False)]
        assert not any(o.gated for o in opened_sessions)
        assert len(env.pids) == len(env.slices)
        env.reset(seed=0)
        env.step(np.zeros((16, 2), np.float32))
    finally:
        env.close()


def test_a_scene_whose_python_runs_per_world_is_not_probed(opened_sessions):
    scene = os.path.join(os.path.dirname(__file__), "scenes", "per_world_scene.py")
    env = RemoteVectorEnv(scene, num_envs=16)
    env.close()
    measured = cost_may_change_layout(16)
    opened = [(o.processes, o.worlds_each, o.measured, o.probe) for o in opened_sessions]
    assert opened == [(len(env.slices), env.envs_per_process, measured, False)]  # the first launch, kept
    assert not any(o.gated for o in opened_sessions)


def test_an_explicit_layout_is_kept_and_not_measured():
    env = RemoteVectorEnv(HOOK_RENDER, num_envs=4, envs_per_process=4)
    try:
        assert env.envs_per_process == 4 and env.world_cost_s is None and len(env.pids) == 1
    finally:
        env.close()


def test_a_later_vector_env_of_the_scene_starts_in_the_layout_learnt(opened_sessions):
    def opened() -> list[tuple[int, bool]]:
        # measured: in its handshake, or at the layout gate (test_layout_gate.py)
        return [(o.worlds_each, o.measured or o.gated) for o in opened_sessions]

    first = gym.make_vec("remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point").unwrapped
    first.close()
    learnt = first.envs_per_process
    assert opened()[0][1] and all(not measured for _, measured in opened()[1:])  # measured once
    assert opened()[-1][0] == learnt
    opened_sessions.clear()
    later = gym.make_vec("remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point").unwrapped
    try:
        assert opened() == [(learnt, False)]  # started where the first ended, measuring nothing
        assert later.envs_per_process == learnt and later.world_cost_s == first.world_cost_s
        assert len(later.pids) == len(later.slices)
        later.reset(seed=0)
        later.step(np.zeros((16, 2), np.float32))
    finally:
        later.close()
    opened_sessions.clear()
    other = gym.make_vec(
        "remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point", reward_control_weight=0.5
    ).unwrapped
    other.close()
    assert opened()[0][1]  # other scene arguments: measured afresh
