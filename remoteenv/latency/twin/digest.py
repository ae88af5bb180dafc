"""Bit-exact fingerprints of observations, to compare a replay with its recording.

Runs in the agent process. :func:`obs_digest` hashes an observation's exact
bytes (numpy arrays: dtype, shape and raw bytes; maps by sorted key; tuples
and lists in order; other values by ``repr``) with BLAKE2b from the standard
library: two observations have the same digest exactly when they are equal
bit for bit (up to a 64-bit hash collision).
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np


def _feed(h: Any, value: Any) -> None:
    if isinstance(value, np.ndarray) or isinstance(value, np.generic):
        arr = np.ascontiguousarray(value)
        h.update(f"a{arr.dtype.str}{arr.shape}".encode())
        h.update(arr.tobytes())
    elif isinstance(value, dict):
        h.update(f"d{len(value)}".encode())
        for key in sorted(value, key=str):
            h.update(repr(key).encode())
            _feed(h, value[key])
    elif isinstance(value, (tuple, list)):
        h.update(f"t{len(value)}".encode())
        for item in value:
            _feed(h, item)
    else:
        h.update(f"v{type(value).__name__}:{value!r}".encode())


def obs_digest(obs: Any) -> str:
    """16 hex digits that change with any bit of ``obs`` (see the module docs)."""
    h = hashlib.blake2b(digest_size=8)
    _feed(h, obs)
    return h.hexdigest()


__all__ = ["obs_digest"]
