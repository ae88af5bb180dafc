"""The physics of all worlds of a process in one native call: ``mujoco.batch``.

Runs in the sim process. :class:`BatchedWorlds` keeps the state of a
process's worlds (one scene class with :attr:`BaseEnv.stacked_hooks`) in one
``mujoco.batch.Batch`` (MuJoCo 4's, ``persistent``: one ``MjData`` per world
inside it, stepped on its own thread pool, bit-identical to ``mj_step`` on
each world's ``MjData``). A batched step is then one native call for every
world, and the scene's batched hooks read and write stacked arrays of all
worlds at once (:func:`stacked`) instead of visiting each world's ``MjData``.

Each world's own ``MjData`` (``env.data``) stays the state of record outside
batched steps. Two flags per world say which copy is newer: after a batched
step the batch's; after anything read ``env.data`` (a reset, a per-world step,
rendering, an attribute call: :attr:`BaseEnv.data` calls :meth:`BatchedWorlds.pull`,
which copies the batch's ``MjData`` into the world's first) the world's, and
its state row is taken back into the batch before its next batched step.

Without ``mujoco.batch`` (MuJoCo before 4.0) :func:`available` is False and
the stepper uses :class:`~remoteenv.sim.stepping.batch_physics.PhysicsThreads` over
the worlds' own ``MjData``; :func:`stacked` then gathers the same arrays
from them, so a scene's hooks give the same results either way.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

if TYPE_CHECKING:
    from remoteenv.sim.scene.base_env import BaseEnv

try:  # MuJoCo >= 4.0
    from mujoco import batch as _mj_batch
except ImportError:  # pragma: no cover - older MuJoCo
    _mj_batch = None

#: The state a batch row holds: everything ``mj_step`` reads (``mjSTATE_INTEGRATION``).
_STATE = mujoco.mjtState.mjSTATE_INTEGRATION


def available() -> bool:
    """Whether this MuJoCo has ``mujoco.batch`` (4.0 and later)."""
    return _mj_batch is not None


class BatchedWorlds:
    """The worlds ``envs`` (one scene class and frame skip) stepping in one ``mujoco.batch.Batch``.

    Creating it links every world to it (:attr:`BaseEnv.data` then pulls from
    it); :meth:`close` hands each world its latest state back and unlinks it.

    Args:
        envs: the process's worlds, in world order.
        threads: the batch's threads, the caller's included (>= 1).
    """

    def __init__(self, envs: Sequence[BaseEnv], threads: int = 1) -> None:
        if _mj_batch is None:
            raise RuntimeError("mujoco.batch needs MuJoCo >= 4.0")
        self.envs = list(envs)
        n = len(self.envs)
        self.batch = _mj_batch.Batch(self.envs[0].model, n, nthread=max(1, int(threads)), persistent=True)
        self.batch.set_models([env.model for env in self.envs])
        self._rows = self.batch.state
        #: The world's own MjData is newer than its batch row (take it back before stepping).
        self._data_newer = np.ones(n, dtype=np.bool_)
        #: The batch's copy is newer than the world's MjData (copy it out before it is read).
        self._batch_newer = np.zeros(n, dtype=np.bool_)
        # The same two facts as Python flags, read on every step without a numpy call:
        # some world's MjData is newer; every world's batch copy is newer.
        self._some_data_newer = True
        self._every_batch_newer = False
        self._fields: dict[str, np.ndarray] = {}
        for w, env in enumerate(self.envs):
            env._batch_link, env._batch_index = self, w

    # ------------------------------------------------------------ the worlds' MjData

    def pull(self, w: int) -> None:
        """World ``w``'s ``MjData`` is about to be used: bring it up to date, and
        take its state back before the world's next batched step."""
        if self._batch_newer[w]:
            self.batch.get_data(w, self.envs[w]._data)
            self._batch_newer[w] = False
            self._every_batch_newer = False
        self._data_newer[w] = True
        self._some_data_newer = True

    def claim(self, w: int) -> None:
        """World ``w``'s ``MjData`` is about to be rewritten whole (a reset): no copy."""
        self._batch_newer[w] = False
        self._data_newer[w] = True
        self._every_batch_newer = False
        self._some_data_newer = True

    def take_back(self) -> None:
        """Load the state rows of the worlds whose ``MjData`` is newer than their row."""
        if not self._some_data_newer:
            return
        rows, envs = self._rows, self.envs
        for w in np.flatnonzero(self._data_newer).tolist():
            env = envs[w]
            mujoco.mj_getState(env.model, env._data, rows[w], _STATE)
        self._data_newer[:] = False
        self._some_data_newer = False

    # ------------------------------------------------------------ batched steps

    def field(self, name: str) -> np.ndarray:
        """The live ``(n, ...)`` array of every world's ``MjData`` field ``name``
        (state fields writable, derived ones read-only; see ``Batch.bind``)."""
        array = self._fields.get(name)
        if array is None:
            array = self._fields[name] = self.batch.bind(name)
        return array

    def write(self, name: str, ids: np.ndarray | None, values: Any) -> None:
        """Write state field ``name`` of worlds ``ids`` (None: all) in the batch."""
        self.take_back()  # on top of the latest state of each world
        array = self.field(name)
        if ids is None:
            array[...] = values
        else:
            array[ids] = values
        self._mark(ids)

    def reset(self, ids: np.ndarray | None) -> None:
        """Reset worlds ``ids`` (sorted; None: all) in the batch to the model's
        defaults, as ``mj_resetData`` does, derived fields not computed (see :meth:`forward`)."""
        if ids is None:
            self._data_newer[:] = False
        else:
            self._data_newer[ids] = False  # their MjData's state is void, not to be taken back
        self._some_data_newer = bool(self._data_newer.any())
        self.batch.reset(ids, stage=mujoco.mjtStage.mjSTAGE_NONE)
        self._mark(ids)

    def forward(self, ids: np.ndarray | None) -> None:
        """``mj_forward`` on worlds ``ids`` (sorted; None: all) in one call."""
        self.take_back()
        self.batch.forward(ids)
        self._mark(ids)

    def _mark(self, ids: np.ndarray | None) -> None:
        """The batch's copy of worlds ``ids`` (None: all) is now newer than their ``MjData``."""
        if ids is None:
            if not self._every_batch_newer:
                self._batch_newer[:] = True
                self._every_batch_newer = True
        else:
            self._batch_newer[ids] = True

    def step(self, ids: np.ndarray | None, nstep: int) -> None:
        """``nstep`` substeps of worlds ``ids`` (sorted; None: all) in one call."""
        self.take_back()  # state changed through a world's MjData during the hooks
        self.batch.step(ids, nstep=nstep)
        self._mark(ids)

    def close(self) -> None:
        """Give every world its latest state and unlink it (its ``MjData`` is the state again)."""
        for w, env in enumerate(self.envs):
            if env._batch_link is self:
                self.pull(w)
                env._batch_link = None


def sorted_ids(ids: np.ndarray) -> np.ndarray:
    """World indices as the batch's calls take them: sorted, ``int32``."""
    return np.sort(ids).astype(np.int32)


class WorldsState:
    """The stacked ``MjData`` fields of the worlds of one batched step, in request order.

    :meth:`get` returns an ``(n, ...)`` array of a field (a view valid until
    the next step, or a copy: read it, do not keep it); :meth:`set` writes a
    state field (``ctrl``, ``qpos``, ``qvel``, ...) of every world.
    """

    def get(self, name: str) -> np.ndarray:
        raise NotImplementedError

    def set(self, name: str, values: Any) -> None:
        raise NotImplementedError

    def forward(self) -> None:
        """``mj_forward`` on every world: the derived fields (positions,
        velocities, forces) of the state written, as :meth:`BaseEnv.set_state` computes them."""
        raise NotImplementedError

    def reset(self) -> None:
        """Every world to the model's defaults, as ``mj_resetData`` (no derived fields)."""
        raise NotImplementedError


class _BatchState(WorldsState):
    """Worlds ``ids`` (request order; None: all, in world order) of a :class:`BatchedWorlds`."""

    def __init__(self, worlds: BatchedWorlds, ids: np.ndarray | None) -> None:
        self._worlds = worlds
        self._ids = ids

    def get(self, name: str) -> np.ndarray:
        array = self._worlds.field(name)
        return array if self._ids is None else array[self._ids]

    def set(self, name: str, values: Any) -> None:
        self._worlds.write(name, self._ids, values)

    def forward(self) -> None:
        self._worlds.forward(self._sorted())

    def reset(self) -> None:
        self._worlds.reset(self._sorted())

    def _sorted(self) -> np.ndarray | None:
        return None if self._ids is None else sorted_ids(self._ids)


class _DataState(WorldsState):
    """The same arrays gathered from (and written into) each world's own ``MjData``."""

    def __init__(self, envs: Sequence[BaseEnv]) -> None:
        self._envs = envs

    def get(self, name: str) -> np.ndarray:
        return np.array([getattr(env.data, name) for env in self._envs])

    def set(self, name: str, values: Any) -> None:
        values = np.asarray(values)
        for env, value in zip(self._envs, values if values.ndim else [values] * len(self._envs)):
            getattr(env.data, name)[...] = value

    def forward(self) -> None:
        for env in self._envs:
            mujoco.mj_forward(env.model, env.data)

    def reset(self) -> None:
        for env in self._envs:
            mujoco.mj_resetData(env.model, env.data)


class StackedWorlds(list):
    """The worlds a batched hook gets (a list of :class:`BaseEnv`, request order),
    carrying their stacked state (:func:`stacked`)."""

    def __init__(self, envs: Sequence[BaseEnv], state: WorldsState) -> None:
        super().__init__(envs)
        self.state = state


def stacked(envs: Sequence[BaseEnv]) -> WorldsState:
    """The stacked state of the worlds ``envs`` a batched hook was given: the
    batch's arrays on the batched path, else gathered from each world's ``MjData``."""
    state = getattr(envs, "state", None)
    return state if isinstance(state, WorldsState) else _DataState(envs)


def batch_state(worlds: BatchedWorlds, ids: np.ndarray | None) -> WorldsState:
    """The state of worlds ``ids`` (request order; None: all) of ``worlds``."""
    return _BatchState(worlds, ids)


def data_state(envs: Sequence[BaseEnv]) -> WorldsState:
    """The state of ``envs`` read from and written to their own ``MjData``."""
    return _DataState(envs)


__all__ = [
    "BatchedWorlds",
    "StackedWorlds",
    "WorldsState",
    "available",
    "batch_state",
    "data_state",
    "sorted_ids",
    "stacked",
]
