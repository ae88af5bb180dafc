"""Pure validators: does a decoded reply, value or info map follow the spec?

Each function returns a description of the first problem found, or None.
They judge against the spec (:mod:`remoteenv.wire.protocol`,
:mod:`remoteenv.wire.messages.batch_encoding`), not against what the reference server happens
to send, and never echo more than a bounded repr of what they were given.

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.wire.messages.batch_encoding import COLUMN_KINDS
from remoteenv.wire.wire_errors import ERROR_KINDS, short_repr

#: Spaces whose values are numpy arrays of the space's shape and dtype.
ARRAY_SPACES = (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)


def is_int(value: Any) -> bool:
    """A msgpack int (Python ``int``, never ``bool``)."""
    return isinstance(value, int) and not isinstance(value, bool)


def is_number(value: Any) -> bool:
    """A msgpack int or float (never ``bool``)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def type_name(value: Any) -> str:
    return "nil" if value is None else type(value).__name__


def envelope_problem(reply: Any) -> str | None:
    """What is wrong with the outer shape of a reply (``seq``, ``ok``, ``error``), if anything."""
    if not isinstance(reply, dict):
        return f"a reply must be a map, got {type_name(reply)}"
    if not is_int(reply.get("seq")):
        return f"a reply needs an integer 'seq', got {short_repr(reply.get('seq'))}"
    ok = reply.get("ok")
    if not isinstance(ok, bool):
        return f"a reply needs a bool 'ok', got {short_repr(ok)}"
    if ok:
        return None
    error = reply.get("error")
    if not isinstance(error, dict):
        return f"an error reply needs an 'error' map, got {type_name(error)}"
    for key in ("kind", "message", "traceback"):
        if not isinstance(error.get(key), str):
            return f"error.{key} must be a str, got {short_repr(error.get(key))}"
    if error["kind"] not in ERROR_KINDS:
        return f"error kind {short_repr(error['kind'])} is not one of the spec's {sorted(ERROR_KINDS)}"
    return None


def value_problem(space: spaces.Space, value: Any, what: str = "obs") -> str | None:
    """What is wrong with ``value`` as a decoded value of ``space``, if anything.

    Array spaces need a numpy array of exactly the space's dtype and shape
    inside the space; Discrete an int in range; Dict a map of the same keys;
    Tuple a list of the same length; each part checked the same way.
    """
    if isinstance(space, ARRAY_SPACES):
        if not isinstance(value, np.ndarray):
            return f"{what} must be an array for {space}, got {type_name(value)}"
        if value.dtype != space.dtype:
            return f"{what} has dtype {value.dtype}, the space says {space.dtype}"
        if value.shape != space.shape:
            return f"{what} has shape {value.shape}, the space says {space.shape}"
        if not space.contains(value):
            return f"{what} {short_repr(value)} is outside {space}"
        return None
    if isinstance(space, spaces.Discrete):
        if not is_int(value):
            return f"{what} must be an int for {space}, got {type_name(value)}"
        if not space.contains(value):
            return f"{what} {value} is outside {space}"
        return None
    if isinstance(space, spaces.Dict):
        if not isinstance(value, dict):
            return f"{what} must be a map for {space}, got {type_name(value)}"
        if set(value) != set(space.spaces):
            return f"{what} has keys {sorted(value)}, the space has {sorted(space.spaces)}"
        for key, sub in space.spaces.items():
            problem = value_problem(sub, value[key], f"{what}[{key!r}]")
            if problem:
                return problem
        return None
    if isinstance(space, spaces.Tuple):
        if not isinstance(value, (list, tuple)) or len(value) != len(space.spaces):
            return f"{what} must be a list of {len(space.spaces)} for {space}, got {short_repr(value)}"
        for i, (sub, item) in enumerate(zip(space.spaces, value)):
            problem = value_problem(sub, item, f"{what}[{i}]")
            if problem:
                return problem
        return None
    if not space.contains(value):
        return f"{what} {short_repr(value)} is not in {space}"
    return None


def batch_obs_problem(space: spaces.Space, obs: Any, n: int) -> str | None:
    """What is wrong with the ``obs`` of a batch reply for ``n`` worlds, if anything.

    Observations of array spaces all have one shape and dtype, so the spec
    asks for one array of shape ``(n, *obs_shape)``; other spaces send a list
    of ``n`` observations.
    """
    if isinstance(space, ARRAY_SPACES):
        if not isinstance(obs, np.ndarray):
            return f"batch obs must be one array of shape {(n, *space.shape)}, got {type_name(obs)}"
        if obs.shape != (n, *space.shape):
            return f"batch obs has shape {obs.shape}, expected {(n, *space.shape)}"
        rows = list(obs)
    else:
        if not isinstance(obs, list) or len(obs) != n:
            return f"batch obs must be a list of {n}, got {short_repr(obs)}"
        rows = obs
    for w, row in enumerate(rows):
        problem = value_problem(space, row, f"obs of world {w}")
        if problem:
            return problem
    return None


def infos_problem(infos: Any, n: int) -> str | None:
    """What is wrong with a batch reply's ``info`` (the spec's ``infos``) for ``n`` worlds, if anything."""
    if not isinstance(infos, dict) or len({"columns", "maps"} & set(infos)) != 1:
        return f"batch info must be {{'columns': ...}} or {{'maps': ...}}, got {short_repr(infos)}"
    if "maps" in infos:
        maps = infos["maps"]
        if not isinstance(maps, list) or len(maps) != n or not all(isinstance(m, dict) for m in maps):
            return f"info 'maps' must be a list of {n} maps, got {short_repr(maps)}"
        return None
    columns = infos["columns"]
    if not isinstance(columns, dict):
        return f"info 'columns' must be a map, got {type_name(columns)}"
    for key, column in columns.items():
        if not (isinstance(column, list) and len(column) == 2):
            return f"info column {short_repr(key)} must be [values, present], got {short_repr(column)}"
        values, present = column
        if isinstance(values, np.ndarray):  # the spec also allows an array of a numpy dtype
            if values.shape != (n,) or values.dtype.kind not in COLUMN_KINDS:
                return (
                    f"info column {short_repr(key)}: values must be a list of {n} or a numeric array of shape "
                    f"({n},), got {short_repr(values)}"
                )
            values = values.tolist()
        if not (isinstance(values, list) and len(values) == n):
            return f"info column {short_repr(key)}: values must be a list of {n}, got {short_repr(values)}"
        if not (isinstance(present, list) and len(present) == n and all(isinstance(p, bool) for p in present)):
            return f"info column {short_repr(key)}: present must be a list of {n} bools, got {short_repr(present)}"
        kinds = {bool if isinstance(v, bool) else type(v) for v in values}
        if not kinds <= {bool, int, float} or len(kinds) > 1:
            return (
                f"info column {short_repr(key)}: values must be bools, ints or floats of one type, "
                f"got {sorted(k.__name__ for k in kinds)}"
            )
    return None


def list_problem(values: Any, n: int, kind: type, what: str) -> str | None:
    """What is wrong with ``values`` as a list of ``n`` values of Python type ``kind``, if anything."""
    if not isinstance(values, list) or len(values) != n:
        return f"{what} must be a list of {n}, got {short_repr(values)}"
    for w, v in enumerate(values):
        if type(v) is not kind:
            return f"{what}[{w}] must be a {kind.__name__}, got {type_name(v)}"
    return None


def reset_reply_problem(space: spaces.Space, reply: dict[str, Any], what: str = "reset") -> str | None:
    """What is wrong with a ``reset`` reply (``obs`` in ``space``, ``info`` a map), if anything."""
    problem = value_problem(space, reply.get("obs"), f"{what} obs")
    if problem:
        return problem
    if not isinstance(reply.get("info"), dict):
        return f"{what} info must be a map, got {type_name(reply.get('info'))}"
    return None


def step_reply_problem(space: spaces.Space, reply: dict[str, Any], what: str = "step") -> str | None:
    """What is wrong with a ``step`` reply (obs, float reward, bool flags, info map), if anything."""
    problem = value_problem(space, reply.get("obs"), f"{what} obs")
    if problem:
        return problem
    if type(reply.get("reward")) is not float:
        return f"{what} reward must be a float, got {type_name(reply.get('reward'))}"
    for key in ("terminated", "truncated"):
        if not isinstance(reply.get(key), bool):
            return f"{what} {key} must be a bool, got {type_name(reply.get(key))}"
    if not isinstance(reply.get("info"), dict):
        return f"{what} info must be a map, got {type_name(reply.get('info'))}"
    return None


def frame_problem(frame: Any) -> str | None:
    """What is wrong with a render ``frame`` (nil, or a uint8 array H x W x 3), if anything."""
    if frame is None:
        return None
    if not isinstance(frame, np.ndarray):
        return f"frame must be a uint8 array or nil, got {type_name(frame)}"
    if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
        return f"frame must be a uint8 array of shape (H, W, 3), got {frame.dtype} {frame.shape}"
    return None


__all__ = [
    "ARRAY_SPACES",
    "batch_obs_problem",
    "envelope_problem",
    "frame_problem",
    "infos_problem",
    "is_int",
    "is_number",
    "list_problem",
    "reset_reply_problem",
    "step_reply_problem",
    "type_name",
    "value_problem",
]
