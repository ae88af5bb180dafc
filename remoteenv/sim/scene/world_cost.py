"""What one world of a scene costs per control tick, measured in the sim process.

Runs in the sim process, once, when a handshake asks for it (``"world_cost":
true``; reported as the reply's ``metadata["world_cost_s"]``, see
:mod:`remoteenv.wire.protocol`). The agent's default layout reads it: worlds
that cost this much each are spread over more processes
(:func:`remoteenv.agent.vector.vector_layout.default_envs_per_process`).

:func:`step_cost` measures a world's whole control tick, however the scene
spends it: a scratch world made like the served ones is reset and stepped
through :meth:`~remoteenv.sim.scene.base_env.BaseEnv.step` (its
``prepare_step``, the physics, its ``post_step`` and the observation checks,
and the declared cameras' images) with actions drawn from its action space;
a scene that renders in its own hook, or does any other costly work there, is
measured with it. The served worlds are never touched. Without a way to make
a scratch world (a server built around worlds by hand), :func:`world_cost`
is the estimate: physics on a scratch copy of world 0's ``MjData`` plus the
declared cameras' rendering. Each figure is the fastest of a few ticks (the
first, which makes renderers and fills caches, is not counted).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import mujoco

log = logging.getLogger(__name__)

_TRIES = 3
#: The ticks :func:`step_cost` times stop once they have taken this long
#: (seconds): a scene that costs seconds per tick is costly whatever the count.
_BUDGET_S = 0.5


def _fastest(run: Any, tries: int = _TRIES) -> float:
    best = float("inf")
    for _ in range(tries):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def world_cost(env: Any) -> float:
    """Seconds one control tick of ``env`` (a :class:`~remoteenv.sim.scene.base_env.BaseEnv`)
    costs on one thread, estimated: physics, and the camera observation's rendering if it has cameras."""
    model, data = env.model, env.data
    scratch = mujoco.MjData(model)
    mujoco.mj_copyData(scratch, model, data)
    physics = _fastest(lambda: mujoco.mj_step(model, scratch, nstep=env.frame_skip))
    rig = getattr(env, "camera_rig", None)
    if rig is None:
        return physics
    rig.frames(data)  # makes the renderers (not counted)
    return physics + _fastest(lambda: rig.frames(data))


def step_cost(make_world: Callable[[], Any], seed: int = 0, close: bool = True) -> float:
    """Seconds one whole control tick of a world from ``make_world()`` costs on
    one thread: the fastest of :data:`_TRIES` ticks after a first uncounted one
    (fewer once they took :data:`_BUDGET_S`). The world is reset with ``seed``,
    stepped with actions sampled from its action space (seeded alike), reset
    again if its episode ends, and closed (unless ``close`` is False)."""
    world = make_world()
    try:
        world.reset(seed=seed)
        world.action_space.seed(seed)
        best = float("inf")
        spent = 0.0
        for tick in range(_TRIES + 1):
            action = world.action_space.sample()
            start = time.perf_counter()
            terminated = world.step(action)[2]
            took = time.perf_counter() - start
            spent += took
            if tick:
                best = min(best, took)
            if terminated:
                world.reset()
            if tick and spent > _BUDGET_S:
                break
        return best
    finally:
        if close:
            world.close()


def measured_cost(env: Any, make_world: Callable[[], Any] | None, on_world: bool = False) -> float:
    """:func:`step_cost` of a world from ``make_world``, or if there is none (or
    making or stepping one failed: logged) :func:`world_cost`'s estimate for ``env``.
    ``on_world`` (a probe, see :mod:`remoteenv.wire.protocol`): :func:`step_cost`
    of ``env`` itself, which is left reset and stepped, open."""
    if on_world:
        make_world = lambda: env  # noqa: E731
    if make_world is not None:
        try:
            return step_cost(make_world, close=not on_world)
        except Exception as exc:  # the scene's own code: fall back rather than fail the handshake
            log.warning(
                "could not measure a scratch world's step (%s: %.200s); estimating instead", type(exc).__name__, exc
            )
    return world_cost(env)


__all__ = ["measured_cost", "step_cost", "world_cost"]
