"""Batch encodings of ``reset_batch`` / ``step_batch`` replies, both directions.

Part of the wire spec (:mod:`remoteenv.wire.protocol`, "Commands"): the sim
encodes the results of ``n`` worlds with :func:`stack` and
:func:`columnar_infos`; the agent merges them into Gymnasium's vector-info
layout with :func:`merge_infos`.

Both processes use it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

_SCALAR_TYPES: dict[type, tuple[type, str]] = {
    bool: (bool, "|b1"),
    np.bool_: (bool, "|b1"),
    int: (int, "<i8"),
    float: (float, "<f8"),
}


_INT64_MIN, _INT64_MAX = -(2**63), 2**63 - 1

#: numpy kinds an info column's values may have (bool, int, uint, float), in a reply's
#: ``{"columns": ...}`` and in a region's info columns alike.
COLUMN_KINDS = frozenset("biuf")


def columnar_infos(infos: list[dict[str, Any]]) -> dict[str, Any]:
    """Encode the info maps of ``n`` worlds for the wire.

    If every value is a bool, int (within int64) or float (numpy scalars
    included) and each key has one type across the worlds: ``{"columns": {key: [values, mask]}}``
    with ``values`` a list of ``n`` (bool, int or float; zero where the world
    lacks the key), or, when the first world's value is a numpy number, an
    array of its dtype (the dtype Gymnasium's own vector envs would give it), and ``mask`` a list of ``n`` bools saying which worlds have
    it. Otherwise ``{"maps": infos}``. Columns cost one list per key instead
    of ``n`` maps to encode and to merge on the agent side.
    """
    n = len(infos)
    kinds: dict[str, type] = {}
    #: Per key, the numpy dtype of its first value (None: a plain bool, int or float).
    numpy_dtypes: dict[str, np.dtype | None] = {}
    for info in infos:
        for key, value in info.items():
            t = type(value)
            if t is int and not _INT64_MIN <= value <= _INT64_MAX:
                return {"maps": infos}  # a column is int64; a map carries any int (extension type 2)
            if t not in _SCALAR_TYPES:
                if isinstance(value, np.integer):
                    t = int
                elif isinstance(value, np.floating):
                    t = float
                else:
                    return {"maps": infos}
            base = _SCALAR_TYPES[t][0]
            if kinds.setdefault(key, base) is not base:
                return {"maps": infos}
            numpy_dtypes.setdefault(key, value.dtype if isinstance(value, np.number) else None)
    columns: dict[str, Any] = {}
    for key, base in kinds.items():
        dtype = numpy_dtypes[key]
        values = np.zeros(n, dtype=dtype if dtype is not None else np.dtype(_SCALAR_TYPES[base][1]))
        mask = np.zeros(n, dtype=np.bool_)
        for w, info in enumerate(infos):
            if key in info:
                values[w] = info[key]
                mask[w] = True
        # A key whose first value is a numpy scalar goes as an array of its
        # dtype: Gymnasium's vector envs type an info array by its first value.
        columns[key] = [values if dtype is not None else values.tolist(), mask.tolist()]
    return {"columns": columns}


def stack(items: list[Any]) -> Any:
    """One array of shape (n, ...) if every item is an array of one shape and dtype, else the list."""
    first = items[0]
    if isinstance(first, np.ndarray) and all(
        isinstance(x, np.ndarray) and x.shape == first.shape and x.dtype == first.dtype for x in items
    ):
        return np.stack(items)
    return items


#: ``add_info(infos, info, i)``: Gymnasium's ``VectorEnv._add_info`` shape.
AddInfo = Callable[[dict[str, Any], dict[str, Any], int], dict[str, Any]]


def merge_infos(
    infos: dict[str, Any], packed: dict[str, Any], idx: np.ndarray, num_envs: int, add_info: AddInfo
) -> None:
    """Add the infos of worlds ``idx`` (the wire form of :func:`columnar_infos`)
    to ``infos`` in Gymnasium's vector layout (``key`` array plus ``_key`` mask).

    Column values go straight into typed arrays; map-encoded infos, and
    columns whose key already holds another kind of value, go through
    ``add_info`` one world at a time (Gymnasium's own merge rules).
    """
    columns = packed.get("columns")
    if columns is None:
        for j, info in enumerate(packed["maps"]):
            add_info(infos, info, int(idx[j]))
        return
    n = num_envs
    for key, (values, present) in columns.items():
        values, present = np.asarray(values), np.asarray(present, dtype=np.bool_)
        arr = infos.get(key)
        if arr is None:
            arr = infos[key] = np.zeros(n, dtype=values.dtype)
            infos[f"_{key}"] = np.zeros(n, dtype=np.bool_)
        elif not (isinstance(arr, np.ndarray) and arr.shape == (n,) and arr.dtype != object):
            for w in np.flatnonzero(present):
                add_info(infos, {key: values[w].item()}, int(idx[w]))
            continue
        where = idx[present]
        arr[where] = values[present]
        infos[f"_{key}"][where] = True
