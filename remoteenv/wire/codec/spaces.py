"""Gymnasium spaces on the wire: the handshake's ``observation_space`` and
``action_space`` maps (part of the spec in :mod:`remoteenv.wire.protocol`).

Box, Discrete, MultiDiscrete, MultiBinary, Dict and Tuple travel as maps
with a ``"type"`` key; Box bounds are arrays.

A space map from a peer is checked whole before any space is built: at most
:data:`~remoteenv.wire.codec.frame_limits.MAX_SPACE_NODES` spaces nested at most
:data:`~remoteenv.wire.codec.frame_limits.MAX_SPACE_DEPTH` deep, dtypes from the
wire's list, counts and bounds within int64, and one value of the space no
larger than a frame (:func:`value_nbytes` at most
:data:`~remoteenv.wire.codec.frame_limits.MAX_MESSAGE_BYTES`: an observation or
action must fit in a message). So a hostile map costs neither memory nor time.

Both processes use it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.wire.codec.arrays import ARRAY_DTYPES, wire_dtype
from remoteenv.wire.codec.frame_limits import MAX_MESSAGE_BYTES, MAX_SPACE_DEPTH, MAX_SPACE_NODES
from remoteenv.wire.wire_errors import ProtocolError, short_repr

_INT64_MAX = 2**63 - 1
_INT64_MIN = -(2**63)
#: Most dimensions of a space's values (as for arrays on the wire).
_MAX_NDIM = 32


def _wire_dtype(dtype: Any) -> str:
    return wire_dtype(np.dtype(dtype))


def space_to_wire(space: Any) -> dict[str, Any]:
    """Describe a Gymnasium space as a msgpack-able map."""
    if isinstance(space, spaces.Box):
        return {"type": "Box", "low": space.low, "high": space.high, "dtype": _wire_dtype(space.dtype)}
    if isinstance(space, spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, spaces.MultiDiscrete):
        return {"type": "MultiDiscrete", "nvec": space.nvec, "start": space.start, "dtype": _wire_dtype(space.dtype)}
    if isinstance(space, spaces.MultiBinary):
        return {"type": "MultiBinary", "n": list(np.atleast_1d(space.n).tolist())}
    if isinstance(space, spaces.Dict):
        return {"type": "Dict", "spaces": {k: space_to_wire(s) for k, s in space.spaces.items()}}
    if isinstance(space, spaces.Tuple):
        return {"type": "Tuple", "spaces": [space_to_wire(s) for s in space.spaces]}
    raise TypeError(f"space {space!r} cannot be described on the wire")


def value_nbytes(space: spaces.Space) -> int:
    """Bytes of one value of ``space`` as arrays (a Discrete value counts 8)."""
    if isinstance(space, spaces.Dict):
        return sum(value_nbytes(s) for s in space.spaces.values())
    if isinstance(space, spaces.Tuple):
        return sum(value_nbytes(s) for s in space.spaces)
    if isinstance(space, spaces.Discrete):
        return 8
    shape = space.shape or ()
    return math.prod(shape) * np.dtype(space.dtype).itemsize


def space_from_wire(desc: Any) -> Any:
    """Rebuild a Gymnasium space from :func:`space_to_wire`'s map.

    Raises :class:`ProtocolError` naming what is wrong for a map off the spec
    or beyond the limits of the module docstring, before building anything.
    """
    nbytes = _check_tree(desc)
    if nbytes > MAX_MESSAGE_BYTES:
        raise ProtocolError(
            f"a value of this space takes {nbytes} bytes, above the wire's frame limit of "
            f"{MAX_MESSAGE_BYTES} bytes: it could never be sent"
        )
    try:
        return _build(desc)
    except ProtocolError:
        raise
    except (KeyError, TypeError, ValueError, OverflowError) as exc:  # gymnasium's own refusals
        raise ProtocolError(
            f"space map {short_repr(desc)} is refused: {type(exc).__name__}: {short_repr(str(exc))}"
        ) from None


def _check_tree(desc: Any) -> int:
    """Walk the map (no recursion): node count, depth and every leaf's fields;
    returns the bytes of one value."""
    stack: list[tuple[Any, int, str]] = [(desc, 1, "space")]
    nodes = 0
    nbytes = 0
    while stack:
        node, depth, where = stack.pop()
        nodes += 1
        if nodes > MAX_SPACE_NODES:
            raise ProtocolError(f"a space map holds more than {MAX_SPACE_NODES} spaces")
        if depth > MAX_SPACE_DEPTH:
            raise ProtocolError(f"{where} nests spaces deeper than {MAX_SPACE_DEPTH}")
        if not isinstance(node, dict):
            raise ProtocolError(f"{where} must be a space map, got {short_repr(node)}")
        kind = node.get("type")
        if kind in ("Dict", "Tuple"):
            members = node.get("spaces")
            if kind == "Dict":
                if not isinstance(members, dict) or not all(isinstance(k, str) for k in members):
                    raise ProtocolError(f"{where} (Dict) needs a map of named spaces, got {short_repr(members)}")
                stack.extend((s, depth + 1, f"{where}[{short_repr(k, 40)}]") for k, s in members.items())
            else:
                if not isinstance(members, list):
                    raise ProtocolError(f"{where} (Tuple) needs a list of spaces, got {short_repr(members)}")
                stack.extend((s, depth + 1, f"{where}[{i}]") for i, s in enumerate(members))
            continue
        nbytes += _leaf_nbytes(node, kind, where)
        if nbytes > MAX_MESSAGE_BYTES:
            return nbytes
    return nbytes


def _leaf_nbytes(node: dict[str, Any], kind: Any, where: str) -> int:
    """Check one leaf map's fields; the bytes of one of its values."""
    if kind == "Discrete":
        n: Any = node.get("n")
        start: Any = node.get("start", 0)
        if not (_is_int(n) and _is_int(start) and n >= 1 and start >= _INT64_MIN and start + n - 1 <= _INT64_MAX):
            raise ProtocolError(f"{where} (Discrete) needs int n >= 1 and start within int64, got {short_repr(node)}")
        return 8
    if kind == "MultiBinary":
        n = node.get("n")
        if not (isinstance(n, list) and 1 <= len(n) <= _MAX_NDIM and all(_is_int(d) and d >= 1 for d in n)):
            raise ProtocolError(
                f"{where} (MultiBinary) needs n, a list of 1..{_MAX_NDIM} ints >= 1, got {short_repr(n)}"
            )
        return _prod_capped(n)
    if kind == "Box":
        dtype = _dtype(node, where)
        low, high = node.get("low"), node.get("high")
        if not (isinstance(low, np.ndarray) and isinstance(high, np.ndarray) and low.shape == high.shape):
            raise ProtocolError(f"{where} (Box) needs low and high arrays of one shape, got {short_repr(node)}")
        return _prod_capped(low.shape) * dtype.itemsize
    if kind == "MultiDiscrete":
        dtype = _dtype(node, where)
        nvec, start = node.get("nvec"), node.get("start")
        if not (isinstance(nvec, np.ndarray) and nvec.dtype.kind in "iu" and nvec.ndim <= _MAX_NDIM):
            raise ProtocolError(f"{where} (MultiDiscrete) needs nvec, an array of ints, got {short_repr(nvec)}")
        if start is not None and not (
            isinstance(start, np.ndarray) and start.dtype.kind in "iu" and start.shape == nvec.shape
        ):
            raise ProtocolError(f"{where} (MultiDiscrete) start must be nil or an int array like nvec")
        return _prod_capped(nvec.shape) * dtype.itemsize
    raise ProtocolError(f"{where} has unknown space type {short_repr(kind)}")


def _dtype(node: dict[str, Any], where: str) -> np.dtype:
    name = node.get("dtype")
    if name not in ARRAY_DTYPES:
        raise ProtocolError(f"{where} dtype {short_repr(name)} is not one of the wire's {sorted(ARRAY_DTYPES)}")
    return np.dtype(name)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _prod_capped(dims: Any) -> int:
    """The product of ``dims``, stopped once above the frame limit (no huge ints built)."""
    total = 1
    for d in dims:
        total *= int(d)
        if total > MAX_MESSAGE_BYTES:
            return MAX_MESSAGE_BYTES + 1
    return total


def _build(desc: dict[str, Any]) -> Any:
    kind = desc["type"]
    if kind == "Box":
        return spaces.Box(low=desc["low"], high=desc["high"], dtype=np.dtype(desc["dtype"]))
    if kind == "Discrete":
        return spaces.Discrete(desc["n"], start=desc.get("start", 0))
    if kind == "MultiDiscrete":
        return spaces.MultiDiscrete(desc["nvec"], dtype=np.dtype(desc["dtype"]), start=desc.get("start"))
    if kind == "MultiBinary":
        n = desc["n"]
        return spaces.MultiBinary(n[0] if len(n) == 1 else n)
    if kind == "Dict":
        return spaces.Dict({k: _build(s) for k, s in desc["spaces"].items()})
    return spaces.Tuple([_build(s) for s in desc["spaces"]])
