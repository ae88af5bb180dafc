"""The reply of a batched step in which some worlds start an episode, built from the stepped worlds' arrays.

Runs in the sim process (:meth:`BatchCommands._step
<remoteenv.sim.stepping.batch_commands.BatchCommands._step>`). With worlds
that end their episodes at different times (most tasks that terminate),
many vector steps start an episode in some worlds while the others step:
under Gymnasium's next-step autoreset a world resets on the step after its
episode ended (``OP_RESET``), under same-step autoreset within the step that
ended it (``OP_STEP_AUTORESET``, ``OP_STEP_RESET``). The reply of such a step
is the one :meth:`BatchCommands._reply` builds world by world (a result map
per world, then stacked and encoded as columns,
:mod:`remoteenv.wire.messages.batch_encoding`); :func:`autoreset_reply`
builds the same reply from the stepped worlds' arrays at once: their rows,
rewards, flags and info columns placed at their positions, the started
worlds' rows and infos at theirs, and a ``final`` entry for each episode
that ended within the step.

The stepped worlds' results are copied before any world starts (as the
per-world path reads them first), so a scene whose hooks return views of
its state gives the same reply either way.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.wire.codec.scalar_types import describe_scalars
from remoteenv.wire.messages.batch_encoding import columnar_infos, stack
from remoteenv.wire.protocol import OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET

#: Starts the episodes of the given worlds (request positions, in order): their observations and info maps.
Start = Callable[[list[int]], tuple[Any, list[dict[str, Any]]]]


def autoreset_reply(
    batch: BatchResult, ops: Sequence[int], stepped: Sequence[int], start: Start
) -> dict[str, Any] | None:
    """The reply of a ``step_batch`` with ``ops``, one per request position,
    whose positions ``stepped`` (those whose op is not ``OP_RESET``, in
    order) stepped with results ``batch``. The positions that start an
    episode (``OP_RESET``, ``OP_STEP_RESET``, and ``OP_STEP_AUTORESET``
    where the world terminated) start it through ``start(positions)``,
    called once, after the stepped results are read. Exactly the reply
    :meth:`~remoteenv.sim.stepping.batch_commands.BatchCommands._reply`
    builds for that step. None, with ``start`` not called, when ``batch`` is
    not an array batch whose info columns encode as columns (then build it
    world by world)."""
    n = len(ops)
    rows = batch.obs
    if not isinstance(rows, np.ndarray) or rows.ndim < 1 or len(rows) != len(stepped):
        return None
    ended = [
        i
        for i, j in enumerate(stepped)
        if ops[j] == OP_STEP_RESET or (ops[j] == OP_STEP_AUTORESET and batch.terminated[i])
    ]
    kept = list(stepped)
    for i in reversed(ended):
        del kept[i]
    columns = _spread_columns(batch, stepped, kept, n)
    if columns is None:
        return None
    obs = np.empty((n, *rows.shape[1:]), dtype=rows.dtype)
    obs[stepped] = rows
    reward = np.zeros(n, dtype=np.float64)
    reward[stepped] = batch.reward
    terminated = np.zeros(n, dtype=np.bool_)
    terminated[stepped] = batch.terminated
    final: list[Any] = []
    final_types: list[Any] = []
    for i in ended:
        info = batch.world_info(i)
        final.append([stepped[i], batch.world_obs(i), info])
        final_types.append(describe_scalars({"info": info}).get("types", {}).get("info"))
    ends = {stepped[i] for i in ended}
    starts = [j for j in range(n) if ops[j] == OP_RESET or j in ends]
    started_obs: Any = []
    started_infos: list[dict[str, Any]] = []
    if starts:
        started_obs, started_infos = start(starts)
    if not any(started_infos) and _put_rows(obs, starts, started_obs):
        info_wire: dict[str, Any] = {"columns": {key: [values, mask] for key, (values, mask) in columns.items()}}
    else:
        # Started worlds whose observations or infos take another form: position by position, as _reply does.
        obs_list: list[Any] = [None] * n
        infos: list[dict[str, Any]] = [{} for _ in range(n)]
        for j in kept:
            obs_list[j] = obs[j]
            infos[j] = {key: values[j] for key, (values, _) in columns.items()}
        for s, j in enumerate(starts):
            obs_list[j] = started_obs[s]
            infos[j] = started_infos[s]
        obs, info_wire = (
            (started_obs if not kept and isinstance(started_obs, np.ndarray) else stack(obs_list)),
            columnar_infos(infos),
        )
    reply: dict[str, Any] = {
        "obs": obs,
        "reward": reward.tolist(),
        "terminated": terminated.tolist(),
        "truncated": [False] * n,
        "info": info_wire,
        "final": final,
    }
    if any(final_types):
        reply["final_types"] = final_types
    return reply


def _spread_columns(
    batch: BatchResult, stepped: Sequence[int], kept: Sequence[int], n: int
) -> dict[str, tuple[Any, list[bool]]] | None:
    """The stepped worlds' info columns in their wire form
    (:meth:`BatchResult.wire_columns`, as :func:`columnar_infos` encodes
    per-world maps: an array of its dtype, or a list of python scalars) over
    ``n`` positions: a stepped world's value at its position ``stepped[i]``,
    present at positions ``kept`` only (zero elsewhere, as columnar_infos
    fills a world without the key; no column when ``kept`` is empty), with
    their masks. None when the infos do not encode as columns."""
    wire = batch.wire_columns()
    if wire is None:
        return None
    if not kept:
        return {}  # no world keeps its step's infos: none of their keys is in the reply
    mask = [False] * n
    for j in kept:
        mask[j] = True
    absent = [j for j, present in enumerate(mask) if not present]
    out: dict[str, tuple[Any, list[bool]]] = {}
    for key, (values, _) in wire["columns"].items():
        as_list = not isinstance(values, np.ndarray)
        # A list holds python bools, ints or floats of one type: numpy's bool, int64 or float64 hold them exactly.
        spread = np.zeros(n, dtype=type(values[0]) if as_list else values.dtype)
        spread[stepped] = values
        spread[absent] = 0
        out[key] = (spread.tolist() if as_list else spread, list(mask))
    return out


def _put_rows(obs: np.ndarray, starts: Sequence[int], started: Any) -> bool:
    """Write the started worlds' observations into rows ``starts`` of ``obs``
    if each is an array of ``obs``'s row shape and dtype (as stacking the
    per-world rows needs); False otherwise (rows ``starts`` then undefined)."""
    if not starts:
        return True
    row_shape = obs.shape[1:]
    if isinstance(started, np.ndarray):
        if started.shape[1:] != row_shape or started.dtype != obs.dtype or len(started) != len(starts):
            return False
        obs[starts] = started
        return True
    for s, j in enumerate(starts):
        row = started[s]
        if not isinstance(row, np.ndarray) or row.shape != row_shape or row.dtype != obs.dtype:
            return False
        obs[j] = row
    return True


__all__ = ["autoreset_reply"]
