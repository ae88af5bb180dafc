"""What a scene's batched hook returns for the worlds it stepped together.

Runs in the sim process. :meth:`remoteenv.sim.BaseEnv.post_steps` returns a
:class:`BatchResult` for ``n`` worlds at once; :mod:`remoteenv.sim.batch`
turns it into a ``step_batch`` reply. The per-world view of the same
numbers (:meth:`BatchResult.world_info`) is exactly what the scene's
per-world :meth:`~remoteenv.sim.BaseEnv.post_step` would have returned.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: numpy kinds an info column may have, and the python type of one element.
_COLUMN_KINDS = {"b": bool, "i": int, "u": int, "f": float}


@dataclass
class BatchResult:
    """The results of one control tick of ``n`` worlds.

    Attributes:
        obs: ``(n, *obs_shape)`` array, or a list of ``n`` obs.
        reward: float64 array ``(n,)``.
        terminated: bool array ``(n,)``.
        infos: a list of ``n`` info maps, or columns: ``{key: array (n,)}`` of
            bool, int or float, every world having every key.
    """

    obs: Any
    reward: np.ndarray
    terminated: np.ndarray
    infos: list[dict[str, Any]] | dict[str, np.ndarray]

    def world_obs(self, w: int) -> Any:
        """World ``w``'s obs (a fresh array for an array batch)."""
        return self.obs[w].copy() if isinstance(self.obs, np.ndarray) else self.obs[w]

    def world_info(self, w: int) -> dict[str, Any]:
        """World ``w``'s info map, with python scalars where columns hold numpy ones."""
        if isinstance(self.infos, list):
            return self.infos[w]
        return {key: column[w].item() for key, column in self.infos.items()}

    def wire_columns(self) -> dict[str, Any] | None:
        """The infos in the wire's column form (see :func:`remoteenv.wire.batch.columnar_infos`),
        or None if they are maps or a column is not bool, int or float."""
        if isinstance(self.infos, list):
            return None
        n = len(self.reward)
        present = [True] * n
        columns: dict[str, Any] = {}
        for key, column in self.infos.items():
            column = np.asarray(column)
            kind = _COLUMN_KINDS.get(column.dtype.kind)
            if kind is None or column.shape != (n,):
                return None
            wide = column.astype(np.float64 if kind is float else np.int64 if kind is int else np.bool_, copy=False)
            columns[key] = [wide.tolist(), present]
        return {"columns": columns}


__all__ = ["BatchResult"]
