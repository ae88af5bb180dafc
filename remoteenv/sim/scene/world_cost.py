"""What one world of a scene costs per control tick, measured in the sim process.

Runs in the sim process, once, at the first ``handshake`` (reported as its
``metadata["world_cost_s"]``, see :mod:`remoteenv.wire.protocol`): the
physics of one tick on one thread (``mj_step`` x ``frame_skip`` on a scratch
copy of the world's ``MjData``, so the world is untouched) plus, for a scene
with cameras, rendering its camera observation once. Each is the fastest of a
few tries (the first render, which makes the renderer, is not counted). The
agent's default layout reads it: worlds that cost this much each are spread
over more processes (:func:`remoteenv.agent.vector.vector_layout.default_envs_per_process`).
"""

from __future__ import annotations

import time
from typing import Any

import mujoco

_TRIES = 3


def _fastest(run: Any, tries: int = _TRIES) -> float:
    best = float("inf")
    for _ in range(tries):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def world_cost(env: Any) -> float:
    """Seconds one control tick of ``env`` (a :class:`~remoteenv.sim.scene.base_env.BaseEnv`)
    costs on one thread: physics, and the camera observation's rendering if it has cameras."""
    model, data = env.model, env.data
    scratch = mujoco.MjData(model)
    mujoco.mj_copyData(scratch, model, data)
    physics = _fastest(lambda: mujoco.mj_step(model, scratch, nstep=env.frame_skip))
    rig = getattr(env, "camera_rig", None)
    if rig is None:
        return physics
    rig.frames(data)  # makes the renderers (not counted)
    return physics + _fastest(lambda: rig.frames(data))


__all__ = ["world_cost"]
