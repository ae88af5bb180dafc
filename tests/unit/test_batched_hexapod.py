"""The hexapod's batched hooks (stacked state, one mujoco.batch call) against its
per-world hooks: byte-identical ``step_batch`` replies, contacts, resets and
autoresets included (the checks of test_batched_scenes, for the heavy scene)."""

from __future__ import annotations

import numpy as np
import pytest
from unit.test_batched_scenes import K, _requests, _scene_class

from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.wire import protocol

Hexapod = _scene_class("hexapod", "HexapodEnv")


def _commands(batched: bool, threads: int) -> BatchCommands:
    envs = [Hexapod() for _ in range(K)]
    commands = BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0, threads=threads)
    if not batched:
        commands.close()
        commands.stepper = None
    return commands


@pytest.mark.parametrize("threads", [1, 2])
def test_hexapod_batched_and_per_world_paths_give_identical_replies(threads: int) -> None:
    batched, per_world = _commands(True, threads), _commands(False, threads)
    assert batched.stepper is not None and batched.stepper.batched is not None
    space = batched.worlds[0].env.action_space
    try:
        seeds = {"worlds": list(range(K)), "seeds": [5 * w for w in range(K)], "options": None}
        assert protocol.pack(batched.reset_batch(dict(seeds), None, None)) == protocol.pack(
            per_world.reset_batch(dict(seeds), None, None)
        )
        finals = 0
        for msg in _requests(space, 150, seed=threads):
            a = batched.step_batch(dict(msg), None, None)
            b = per_world.step_batch(dict(msg), None, None)
            assert protocol.pack(a) == protocol.pack(b), msg
            finals += len(a["final"])
        assert finals > 5
        for wa, wb in zip(batched.worlds, per_world.worlds):
            np.testing.assert_array_equal(wa.env.data.qpos, wb.env.data.qpos)
            np.testing.assert_array_equal(wa.env.data.actuator_force, wb.env.data.actuator_force)
    finally:
        batched.close()
        for w in batched.worlds + per_world.worlds:
            w.env.close()
