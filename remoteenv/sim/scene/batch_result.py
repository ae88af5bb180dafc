"""What a scene's batched hook returns for the worlds it stepped together.

Runs in the sim process. :meth:`remoteenv.sim.BaseEnv.post_steps` returns a
:class:`BatchResult` for ``n`` worlds at once; :mod:`remoteenv.sim.stepping.batch_commands`
turns it into a ``step_batch`` reply. The per-world view of the same
numbers (:meth:`BatchResult.world_info`) is exactly what the scene's
per-world :meth:`~remoteenv.sim.BaseEnv.post_step` would have returned.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from remoteenv.wire.messages.batch_encoding import COLUMN_KINDS

#: The dtype whose ``tolist()`` gives the python scalars of a column of each kind (:data:`COLUMN_KINDS`).
_WIDE = {"b": np.bool_, "i": np.int64, "u": np.int64, "f": np.float64}
_INT64 = np.iinfo(np.int64)


def widened(column: np.ndarray) -> np.ndarray | None:
    """An info column of python scalars (or of numpy bools) in the dtype whose
    ``tolist()`` gives them: bool, int64 or float64. None when a value does
    not fit (a uint64 above int64's range, which only a per-world map carries,
    as :func:`~remoteenv.wire.messages.batch_encoding.columnar_infos` sends it)."""
    kind = column.dtype.kind
    if kind == "u" and column.size and column.max() > _INT64.max:
        return None
    return column.astype(_WIDE[kind], copy=False)


@dataclass
class BatchResult:
    """The results of one control tick of ``n`` worlds.

    Attributes:
        obs: ``(n, *obs_shape)`` array, or a list of ``n`` obs.
        reward: float64 array ``(n,)``.
        terminated: bool array ``(n,)``.
        infos: a list of ``n`` info maps, or columns, every world having
            every key: ``{key: values}`` with ``values`` a numpy array ``(n,)``
            of a bool, int or float dtype (world ``w``'s value is then the
            numpy scalar ``values[w]``, as a per-world hook returning numpy
            scalars gives it) or a list of ``n`` python bools, ints or floats.
        python_scalars: the keys of array columns that stand for python bools,
            ints or floats (world ``w``'s value is ``values[w].item()``, and the
            column travels as a list), as a per-world hook returning python
            numbers gives them, without a list built per step.
    """

    obs: Any
    reward: np.ndarray
    terminated: np.ndarray
    infos: list[dict[str, Any]] | dict[str, Any]
    python_scalars: frozenset[str] = field(default_factory=frozenset)

    def world_obs(self, w: int) -> Any:
        """World ``w``'s obs (a fresh array for an array batch)."""
        return self.obs[w].copy() if isinstance(self.obs, np.ndarray) else self.obs[w]

    def world_info(self, w: int) -> dict[str, Any]:
        """World ``w``'s info map (numpy scalars from array columns, python ones from lists)."""
        if isinstance(self.infos, list):
            return self.infos[w]
        python = self.python_scalars
        return {key: column[w].item() if key in python else column[w] for key, column in self.infos.items()}

    def wire_columns(self) -> dict[str, Any] | None:
        """The infos in the wire's column form, exactly as
        :func:`remoteenv.wire.messages.batch_encoding.columnar_infos` encodes the per-world maps
        (an array column goes as an array of its dtype, a list as a list), or
        None if they are maps or a column is not bool, int or float."""
        if isinstance(self.infos, list):
            return None
        n = len(self.reward)
        present = [True] * n
        columns: dict[str, Any] = {}
        for key, column in self.infos.items():
            if isinstance(column, np.ndarray):
                if column.dtype.kind not in COLUMN_KINDS or column.shape != (n,):
                    return None
                # A numpy bool is no numpy number: its column goes as a list, as columnar_infos sends it.
                if key in self.python_scalars or column.dtype.kind == "b":
                    wide = widened(column)
                    if wide is None:
                        return None
                    columns[key] = [wide.tolist(), present]
                else:
                    columns[key] = [np.ascontiguousarray(column), present]
                continue
            if len(column) != n or not all(type(v) in (bool, int, float) for v in column):
                return None
            kinds = {type(v) for v in column}
            if len(kinds) > 1:
                return None
            if int in kinds and not all(_INT64.min <= v <= _INT64.max for v in column):
                return None  # a column is int64; a per-world map carries any int
            columns[key] = [list(column), present]
        return {"columns": columns}


__all__ = ["BatchResult", "widened"]
