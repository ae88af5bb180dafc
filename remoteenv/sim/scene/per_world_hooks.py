"""The default batched hooks of a scene: each world's own hook, in turn.

Runs in the sim process. :meth:`BaseEnv.prepare_steps <remoteenv.sim.scene.base_env.BaseEnv.prepare_steps>`
and :meth:`~remoteenv.sim.scene.base_env.BaseEnv.post_steps` call these
unless a scene overrides them with numpy over all worlds at once. ``envs``
are the worlds (:class:`~remoteenv.sim.scene.base_env.BaseEnv` instances;
typed loosely here, as this module sits below ``base_env``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.scene.step_check import unpack_step


def per_world(actions: Any) -> Any:
    """Batched actions as the per-world hooks get them (python ints for Discrete)."""
    if isinstance(actions, np.ndarray) and actions.dtype.kind in "iu":
        return actions.tolist()
    return actions


def prepare_each(envs: Sequence[Any], actions: Any) -> None:
    """``envs[i].prepare_step(actions[i])`` for every world."""
    for env, action in zip(envs, per_world(actions)):
        env.prepare_step(action)


def post_each(envs: Sequence[Any], actions: Any, scene: str) -> BatchResult:
    """Every world's ``post_step``, each result checked (``scene``: the class name
    for messages), stacked into a :class:`BatchResult`."""
    obs, rewards, terminated, infos = [], [], [], []
    for env, action in zip(envs, per_world(actions)):
        o, r, t, info = unpack_step(env.post_step(action), scene=scene, hook="post_step", finite=env.check_finite)
        obs.append(o)
        rewards.append(float(r))
        terminated.append(bool(t))
        infos.append(info)
    return BatchResult(obs, np.array(rewards, dtype=np.float64), np.array(terminated, dtype=np.bool_), infos)


__all__ = ["per_world", "post_each", "prepare_each"]
