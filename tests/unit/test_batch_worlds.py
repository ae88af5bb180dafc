"""The worlds of a process in one mujoco.batch: each world's ``data`` kept exact,
changes made through it taken back, and the same results without mujoco.batch."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from unit.test_batched_scenes import K, _requests, _scene_class

from remoteenv.sim.stepping import batch_worlds
from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.batch_worlds import BatchedWorlds, StackedWorlds, batch_state, stacked
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.wire import protocol

Reacher = _scene_class("reacher", "ReacherEnv")


def _reachers(n: int) -> list:
    envs = [Reacher() for _ in range(n)]
    for w, env in enumerate(envs):
        env.reset(seed=w)
    return envs


def _serial_step(envs: list, actions: np.ndarray) -> None:
    for env, action in zip(envs, actions):
        env.data.ctrl[:] = action
        mujoco.mj_step(env.model, env.data, nstep=env.frame_skip)


def test_a_worlds_data_reads_as_mj_step_left_it_and_changes_to_it_count() -> None:
    batched_envs, serial = _reachers(3), _reachers(3)
    worlds = BatchedWorlds(batched_envs)
    rng = np.random.default_rng(0)
    try:
        for t in range(30):
            actions = rng.uniform(-1, 1, size=(3, 2))
            stacked(StackedWorlds(batched_envs, batch_state(worlds, None))).set("ctrl", actions)
            worlds.step(None, 2)
            _serial_step(serial, actions)
            if t == 10:  # a change made through one world's MjData between batched steps
                for env in (batched_envs[1], serial[1]):
                    env.data.qvel[0] += 0.5
                    mujoco.mj_forward(env.model, env.data)
            if t % 7 == 0:
                for a, b in zip(batched_envs, serial):
                    for field in ("qpos", "qvel", "xpos", "qacc", "actuator_force"):
                        np.testing.assert_array_equal(getattr(a.data, field), getattr(b.data, field))
        state = batch_state(worlds, np.array([2, 0]))
        np.testing.assert_array_equal(state.get("qpos"), [serial[2].data.qpos, serial[0].data.qpos])
    finally:
        worlds.close()
    assert all(env._batch_link is None for env in batched_envs)
    for a, b in zip(batched_envs, serial):  # handed back on close
        np.testing.assert_array_equal(a.data.qpos, b.data.qpos)


def test_without_mujoco_batch_the_batched_path_gives_the_same_replies(monkeypatch: pytest.MonkeyPatch) -> None:
    def commands() -> BatchCommands:
        envs = [Reacher() for _ in range(K)]
        return BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0)

    with_batch = commands()
    monkeypatch.setattr(batch_worlds, "_mj_batch", None)
    without = commands()
    assert with_batch.stepper is not None and with_batch.stepper.batched is not None
    assert without.stepper is not None and without.stepper.batched is None
    space = with_batch.worlds[0].env.action_space
    try:
        seeds = {"worlds": list(range(K)), "seeds": list(range(K)), "options": None}
        with_batch.reset_batch(dict(seeds), None, None)
        without.reset_batch(dict(seeds), None, None)
        for msg in _requests(space, 120, seed=9):
            a, b = with_batch.step_batch(dict(msg), None, None), without.step_batch(dict(msg), None, None)
            assert protocol.pack(a) == protocol.pack(b), msg
    finally:
        for commands_ in (with_batch, without):
            commands_.close()
            for w in commands_.worlds:
                w.env.close()
