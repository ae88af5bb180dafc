"""The batched hooks of a scene and their default: each world's own hook, in turn.

Runs in the sim process. :meth:`BatchedHooks.prepare_steps`,
:meth:`BatchedHooks.post_steps` and :meth:`BatchedHooks.reset_models` (which :class:`~remoteenv.sim.scene.base_env.BaseEnv`
inherits) call these unless a scene overrides them with numpy over all worlds
at once. ``envs`` are the worlds (:class:`~remoteenv.sim.scene.base_env.BaseEnv` instances;
typed loosely here, as this module sits below ``base_env``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.scene.step_check import unpack_reset, unpack_step


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


def reset_each(
    envs: Sequence[Any], options: dict[str, Any] | None, scene: str
) -> tuple[list[Any], list[dict[str, Any]]]:
    """Every world's ``reset_model(options)``, each result checked (``scene``: the
    class name for messages): the obs and the infos, one per world."""
    obs, infos = [], []
    for env in envs:
        o, info = unpack_reset(env.reset_model(options), scene=scene)
        obs.append(o)
        infos.append(info)
    return obs, infos


class BatchedHooks:
    """The optional batched hooks of a scene (:class:`~remoteenv.sim.scene.base_env.BaseEnv`
    is one), each world's own hook in turn unless the scene overrides them."""

    @classmethod
    def prepare_steps(cls, envs: Sequence[Any], actions: Any) -> None:
        """Optional batched :meth:`prepare_step`: apply ``actions[i]`` to ``envs[i]``.

        A lock-step sim without action or observation delays steps the worlds of one
        ``step_batch`` request together: ``prepare_steps``, then the physics of
        every world on threads (:mod:`remoteenv.sim.stepping.batch_physics`), then
        :meth:`post_steps`. ``envs`` are worlds of this class; ``actions``
        are checked and stacked: an array ``(n, *shape)`` for a Box space,
        an int array ``(n,)`` for Discrete, else a list; never None. The
        default calls :meth:`prepare_step` per world; a scene may override
        both hooks to work with numpy over all worlds at once, and must then
        give exactly the per-world hooks' results (a test should say so).
        """
        prepare_each(envs, actions)

    @classmethod
    def post_steps(cls, envs: Sequence[Any], actions: Any) -> BatchResult:
        """Optional batched :meth:`post_step` for ``envs`` after their substeps
        (see :meth:`prepare_steps`). The default calls :meth:`post_step` per world."""
        return post_each(envs, actions, cls.__name__)

    @classmethod
    def reset_models(cls, envs: Sequence[Any], options: dict[str, Any] | None) -> tuple[Any, list[dict[str, Any]]]:
        """Optional batched :meth:`reset_model`: put every world of ``envs`` into a
        start state drawn from its own ``np_random``; returns ``(obs, infos)``,
        ``obs`` an array ``(n, *obs_shape)`` or a list of ``n`` obs, ``infos`` a
        list of ``n`` dicts.

        Called when worlds of a lock-step sim without delays start an episode
        in one request (a vector env's reset, its autoresets), with every
        world already reset to the model's defaults (as ``mj_resetData``
        leaves it). A scene with :attr:`stacked_hooks` may write the start
        states into ``stacked(envs)`` (``set``), compute the derived
        quantities of all worlds in one call (``forward()``, as
        :meth:`set_state`'s ``mj_forward``) and read them stacked; it must
        draw exactly what :meth:`reset_model` draws from each world's
        ``np_random``, so the worlds' start states and observations are the
        per-world hook's, bit for bit (a test should say so). The default
        calls :meth:`reset_model` per world."""
        return reset_each(envs, options, cls.__name__)


__all__ = ["BatchedHooks", "per_world", "post_each", "prepare_each", "reset_each"]
