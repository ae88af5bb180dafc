"""Gymnasium spaces on the wire: the handshake's ``observation_space`` and
``action_space`` maps (part of the spec in :mod:`remoteenv.wire.protocol`).

Box, Discrete, MultiDiscrete, MultiBinary, Dict and Tuple travel as maps
with a ``"type"`` key; Box bounds are arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.wire.errors import ProtocolError
from remoteenv.wire.protocol import wire_dtype


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


def space_from_wire(desc: dict[str, Any]) -> Any:
    """Rebuild a Gymnasium space from :func:`space_to_wire`'s map."""
    kind = desc.get("type")
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
        return spaces.Dict({k: space_from_wire(s) for k, s in desc["spaces"].items()})
    if kind == "Tuple":
        return spaces.Tuple([space_from_wire(s) for s in desc["spaces"]])
    raise ProtocolError(f"unknown space type {kind!r}")
