"""The sim's end of the layout gate: what it reports of a scratch world (its waiting: tests/integration/test_layout_gate.py)."""

from __future__ import annotations

import json
import math
import os

from remoteenv.benchmarks.harness.step_profile import reacher_class
from remoteenv.sim.process.layout_gate import facts_of
from remoteenv.sim.stepping.batch_worlds import available
from remoteenv.wire.messages.handshake import worlds_that_fit


def test_the_facts_of_a_world():
    world = reacher_class()()
    try:
        facts = facts_of(world, 2.5e-05)
        assert facts == {
            "world_cost_s": 2.5e-05,
            "stacked_hooks": available(),  # Reacher's hooks are stacked: one batch wherever mujoco.batch is
            "worlds_that_fit": worlds_that_fit(world.observation_space),
            "pid": os.getpid(),
        }
        assert facts_of(world, math.inf)["world_cost_s"] is None
        json.dumps(facts, allow_nan=False)
    finally:
        world.close()


def test_a_world_whose_class_steps_world_by_world_is_said_so():
    reacher = reacher_class()
    per_world = type("PerWorldReacher", (reacher,), {"stacked_hooks": False})
    world = per_world()
    try:
        assert facts_of(world, 1e-5)["stacked_hooks"] is False
    finally:
        world.close()
