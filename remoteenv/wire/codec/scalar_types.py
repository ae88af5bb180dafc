"""numpy scalar types of a reply's reward and info values, both directions.

Part of the spec (:mod:`remoteenv.wire.protocol`, "Values"): numpy scalars
travel as plain msgpack numbers, which loses their type; Gymnasium's own
MuJoCo envs return an ``np.float64`` reward and, e.g., an ``np.float32``
``info["reward_ctrl"]``, and a strict comparison
(``gymnasium.utils.env_match.check_environments_match``) tells them apart.
So the sim adds a ``"types"`` map to a ``reset``/``step`` reply that had
such values (:func:`describe_scalars`), and the agent casts them back
(:func:`restore_scalars`). A reply with only plain values carries no map.
The map is a hint: a name the client does not know, or a value its type
cannot hold, leaves the value as it came.

Both processes use it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from remoteenv.wire.codec.arrays import ARRAY_DTYPES

#: The numpy scalar type of each wire dtype name.
_SCALAR_TYPE = {name: np.dtype(name).type for name in ARRAY_DTYPES}
#: Wire dtype name (or None) by numpy dtype, filled as dtypes are met: every step sees the same few.
_NAMES: dict[np.dtype, str | None] = {}


def _wire_name(value: Any) -> str | None:
    if isinstance(value, (np.integer, np.floating)):  # np.bool_ stays a plain bool, as before
        dtype = value.dtype
        try:
            return _NAMES[dtype]
        except KeyError:
            name = dtype.newbyteorder("<").str if dtype.itemsize > 1 else dtype.str
            _NAMES[dtype] = name if name in ARRAY_DTYPES else None
            return _NAMES[dtype]
    return None


def describe_scalars(reply: dict[str, Any]) -> dict[str, Any]:
    """Add ``reply["types"]`` naming the numpy scalar types of ``reward`` and of
    the top-level ``info`` values, when there are any; returns ``reply``."""
    types: dict[str, Any] = {}
    reward = _wire_name(reply.get("reward"))
    if reward is not None:
        types["reward"] = reward
    info = reply.get("info")
    if isinstance(info, dict):
        info_types = {}
        for key, value in info.items():
            name = _wire_name(value)
            if name is not None:
                info_types[key] = name
        if info_types:
            types["info"] = info_types
    if types:
        reply["types"] = types
    return reply


def restore_info(info: Any, info_types: Any) -> Any:
    """Cast the values of the info map ``info`` named in ``info_types`` (``{key:
    dtype}``, as in a ``"types"`` map's ``"info"``) back to numpy scalars, in place."""
    if isinstance(info, dict) and isinstance(info_types, dict):
        for key, name in info_types.items():
            if isinstance(key, str) and key in info:
                info[key] = _typed(info[key], name)
    return info


def restore_scalars(reply: dict[str, Any]) -> dict[str, Any]:
    """Cast ``reward`` and ``info`` values named in ``reply["types"]`` back to
    their numpy scalar types (and drop the map); returns ``reply``. Names
    outside :data:`~remoteenv.wire.protocol.ARRAY_DTYPES`, and values that are
    not plain numbers, are left as they are."""
    types = reply.pop("types", None)
    if not isinstance(types, dict):
        return reply
    if "reward" in reply:
        reply["reward"] = _typed(reply["reward"], types.get("reward"))
    restore_info(reply.get("info"), types.get("info"))
    return reply


def _typed(value: Any, name: Any) -> Any:
    """``value`` as the numpy scalar type ``name``, if it is a plain number that
    type holds (the same number, or for floats no overflow to infinity); else ``value``."""
    if not isinstance(value, (bool, int, float)) or not isinstance(name, str):
        return value
    cast = _SCALAR_TYPE.get(name)
    if cast is None:
        return value
    try:
        with np.errstate(over="ignore"):
            typed = cast(value)
    except (OverflowError, ValueError):
        return value
    if isinstance(value, float) and np.isinf(typed) and not np.isinf(value):
        return value
    return typed


__all__ = ["describe_scalars", "restore_info", "restore_scalars"]
