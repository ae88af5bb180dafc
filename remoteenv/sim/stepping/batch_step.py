"""One control tick for many worlds of one process: batched hooks, batched physics.

Runs in the sim process (lock-step, no action or observation delay). :class:`WorldsStepper`
drives a ``step_batch`` request's stepped worlds as
:meth:`BaseEnv.prepare_steps` -> physics of every world -> :meth:`BaseEnv.post_steps`.
The physics of a scene with :attr:`~BaseEnv.stacked_hooks` runs in one native
call over all the worlds (:class:`~remoteenv.sim.stepping.batch_worlds.BatchedWorlds`,
MuJoCo's ``mujoco.batch``), and its hooks work on stacked arrays of all the
worlds' state (:func:`~remoteenv.sim.stepping.batch_worlds.stacked`); other scenes'
physics runs on threads over each world's ``MjData``
(:class:`~remoteenv.sim.stepping.batch_physics.PhysicsThreads`). Scenes that keep the
per-world hooks get the same sequence per world (``BaseEnv``'s default
batched hooks loop over them), so every scene's physics runs off the GIL.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.scene.camera_rig import observe_worlds
from remoteenv.sim.scene.obs_check import rows_fit
from remoteenv.sim.scene.step_check import check_batch, check_reset_batch
from remoteenv.sim.stepping.batch_physics import PhysicsThreads, default_threads
from remoteenv.sim.stepping.batch_worlds import (
    BatchedWorlds,
    StackedWorlds,
    available,
    batch_state,
    data_state,
    sorted_ids,
)


def steps_together(envs: Sequence[Any]) -> bool:
    """Whether ``envs`` can be stepped as one batch: ``BaseEnv`` worlds of one
    class and frame skip, that keep BaseEnv's ``step`` and have no viewer
    window (which wants a sync after every world's step)."""
    if not envs or not all(isinstance(env, BaseEnv) for env in envs):
        return False
    cls = type(envs[0])
    return (
        cls.step is BaseEnv.step
        and all(type(env) is cls and env.frame_skip == envs[0].frame_skip for env in envs)
        and all(getattr(env, "_viewer", None) is None for env in envs)
    )


def steps_as_one_batch(envs: Sequence[Any]) -> bool:
    """Whether ``envs`` step in one ``mujoco.batch`` call with their scene's
    stacked hooks: they step together (:func:`steps_together`), their class
    sets :attr:`~BaseEnv.stacked_hooks` and this MuJoCo has ``mujoco.batch``."""
    return steps_together(envs) and bool(type(envs[0]).stacked_hooks) and available()


def _overrides(cls: type[BaseEnv], hook: str) -> bool:
    """Whether scene class ``cls`` has its own batched ``hook`` (not BaseEnv's per-world default)."""
    return getattr(getattr(cls, hook), "__func__", None) is not getattr(getattr(BaseEnv, hook), "__func__", None)


class WorldsStepper:
    """Steps any subset of ``envs`` (one class, see :func:`steps_together`) by one tick.

    Args:
        envs: the process's worlds, in world order.
        threads: physics threads (default :func:`~remoteenv.sim.stepping.batch_physics.default_threads`).
    """

    def __init__(self, envs: Sequence[BaseEnv], threads: int | None = None) -> None:
        if not steps_together(envs):
            raise ValueError("WorldsStepper needs BaseEnv worlds of one class and frame skip, without viewer")
        self.envs = list(envs)
        self._cls = type(self.envs[0])
        self._models = [env.model for env in self.envs]
        self._datas = [env.data for env in self.envs]
        self._frame_skip = self.envs[0].frame_skip
        #: The hook that produced a batch's results, as its errors name it.
        self._hook = "post_steps" if _overrides(self._cls, "post_steps") else "post_step"
        #: The scene resets worlds together (its own ``reset_models``).
        self.resets_together = _overrides(self._cls, "reset_models")
        self._all = list(range(len(self.envs)))
        nthreads = threads if threads is not None else default_threads(len(self.envs))
        #: Threads the worlds' physics steps on, the caller's included.
        self.threads = max(1, int(nthreads))
        #: The worlds' physics in one ``mujoco.batch.Batch`` (scenes with stacked hooks), else None.
        self.batched = BatchedWorlds(self.envs, nthreads) if steps_as_one_batch(self.envs) else None
        self.physics = PhysicsThreads(1 if self.batched is not None else nthreads)
        #: Every world, with the batch's state (the common request: built once).
        self._every = StackedWorlds(self.envs, batch_state(self.batched, None)) if self.batched is not None else None

    def step(
        self,
        worlds: Sequence[int],
        actions: Any,
        obs_out: np.ndarray | None = None,
        after_physics: Callable[[], None] | None = None,
    ) -> BatchResult:
        """One tick of worlds ``worlds`` (indices, in order) with ``actions[j]``
        for ``worlds[j]`` (checked and stacked, see :meth:`BaseEnv.prepare_steps`).
        ``obs_out``: where camera images alone (one camera, no state) may be
        rendered in place, e.g. the shared region's rows (see
        :func:`~remoteenv.sim.scene.camera_rig.observe_worlds`).
        ``after_physics``: called once the physics is done, before the
        scene's ``post_steps`` (the fast lane's heads-up)."""
        every = list(worlds) == self._all
        batched = self.batched
        if batched is not None:
            if every and self._every is not None:
                envs: Sequence[BaseEnv] = self._every
                self._cls.prepare_steps(envs, actions)
                batched.step(None, self._frame_skip)
            else:
                ids = np.asarray(worlds, dtype=np.intp)
                envs = StackedWorlds([self.envs[w] for w in worlds], batch_state(batched, ids))
                self._cls.prepare_steps(envs, actions)
                batched.step(sorted_ids(ids), self._frame_skip)
        else:
            if every:
                envs, models, datas = self.envs, self._models, self._datas
            else:
                envs = [self.envs[w] for w in worlds]
                models = [self._models[w] for w in worlds]
                datas = [self._datas[w] for w in worlds]
            self._cls.prepare_steps(envs, actions)
            self.physics.step(models, datas, self._frame_skip)
        if after_physics is not None:
            after_physics()
        env = self.envs[0]
        result = check_batch(
            self._cls.post_steps(envs, actions),
            len(envs),
            scene=self._cls.__name__,
            hook=self._hook,
            finite=env.check_finite,
        )
        self._check_obs(result.obs, self._hook)
        if env.camera_rig is not None:
            result.obs = observe_worlds(envs, result.obs, obs_out)
        return result

    def reset(self, worlds: Sequence[int], options: dict[str, Any] | None) -> tuple[Any, list[dict[str, Any]], Any]:
        """Start an episode in worlds ``worlds`` (indices, in order; their RNGs
        seeded already if the request seeds them) through the scene's
        :meth:`~BaseEnv.reset_models` (only when :attr:`resets_together`):
        ``(obs, infos, times)``, one per world in request order, ``times`` the
        worlds' ``data.time`` after the reset (seconds). The same as each
        world's :meth:`BaseEnv.reset`, in one batched call."""
        if self.batched is not None:
            if list(worlds) == self._all and self._every is not None:
                envs = self._every
            else:
                ids = np.asarray(worlds, dtype=np.intp)
                envs = StackedWorlds([self.envs[w] for w in worlds], batch_state(self.batched, ids))
        else:
            chosen = [self.envs[w] for w in worlds]
            envs = StackedWorlds(chosen, data_state(chosen))
        envs.state.reset()
        env = self.envs[0]
        obs, infos = check_reset_batch(
            self._cls.reset_models(envs, options), len(envs), scene=self._cls.__name__, finite=env.check_finite
        )
        self._check_obs(obs, "reset_models")
        times = envs.state.get("time")
        if env.camera_rig is not None:
            obs = [world.observe(obs[j], fresh=True) for j, world in enumerate(envs)]
        return obs, infos, times

    def _check_obs(self, obs: Any, hook: str) -> None:
        """What :meth:`BaseEnv.finish_tick` checks per world: a stacked batch's
        dtype and row shape once (every row shares them), each row's bounds
        when the scene asks for bounds; other batches world by world."""
        env = self.envs[0]
        if isinstance(obs, np.ndarray) and obs.ndim >= 1 and not env.check_obs_bounds:
            if not env.check_finite and len(obs) and rows_fit(env._hooks_obs_space, obs):
                return  # what the first row's check looks at, read off the batch
            rows = obs[:1]
        else:
            rows = obs
        for row in rows:
            env._check_obs(row, hook)

    def close(self) -> None:
        """Stop the physics threads; give every world its state back (its ``MjData``)."""
        self.physics.close()
        if self.batched is not None:
            self.batched.close()
            self.batched = None


__all__ = ["WorldsStepper", "steps_as_one_batch", "steps_together"]
