"""Actions the checks send: gentle valid ones and clearly invalid ones.

A server under test may drive real hardware, so the valid action is the
most neutral one a space has (zeros clipped into a Box, the first value of
a Discrete), never a random one. Invalid actions are outside the space under
any reading of the spec (wrong type, wrong shape, out of range, NaN).

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces


def neutral_action(space: spaces.Space) -> Any:
    """A valid action of ``space`` in its wire form, as gentle as the space allows."""
    if isinstance(space, spaces.Box):
        return np.clip(np.zeros(space.shape), space.low, space.high).astype(space.dtype)
    if isinstance(space, spaces.Discrete):
        return int(space.start)
    if isinstance(space, spaces.MultiDiscrete):
        return np.asarray(space.start, dtype=space.dtype).reshape(space.shape)
    if isinstance(space, spaces.MultiBinary):
        return np.zeros(space.shape, dtype=space.dtype)
    if isinstance(space, spaces.Dict):
        return {key: neutral_action(sub) for key, sub in space.spaces.items()}
    if isinstance(space, spaces.Tuple):
        return [neutral_action(sub) for sub in space.spaces]
    space.seed(0)
    return space.sample()


def stacked_actions(space: spaces.Space, actions: list[Any]) -> Any:
    """``actions`` of ``n`` worlds in the stacked form of ``step_batch``: one
    array for array spaces, an int array for Discrete, else the list."""
    if isinstance(space, (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)):
        return np.stack(actions)
    if isinstance(space, spaces.Discrete):
        return np.asarray(actions, dtype=np.int64)
    return list(actions)


def _above_high(space: spaces.Box) -> Any | None:
    """The neutral action with its first element that can exceed the Box's high bound
    set above it (None if no element can: unbounded, or bounded by the dtype's maximum)."""
    kind = space.dtype.kind
    if kind not in "fiu":
        return None
    dtype: Any = space.dtype
    top = float(np.finfo(dtype).max) if kind == "f" else int(np.iinfo(dtype).max)
    high = np.broadcast_to(space.high, space.shape).reshape(-1)
    for i, bound in enumerate(high.tolist()):
        if math.isfinite(bound) and bound < top:
            action = neutral_action(space).reshape(-1)
            action[i] = min(bound + max(1, abs(bound)), top) if kind == "f" else bound + 1
            return action.reshape(space.shape)
    return None


def invalid_actions(space: spaces.Space) -> list[tuple[str, Any]]:
    """``(label, action)`` pairs, each outside ``space``."""
    found: list[tuple[str, Any]] = [("nil", None), ("a string", "not an action")]
    if isinstance(space, spaces.Box):
        found.append(("an array of the wrong shape", np.zeros((*space.shape, 2), dtype=space.dtype)))
        if space.dtype.kind == "f":
            found.append(("NaN", np.full(space.shape, np.nan, dtype=space.dtype)))
        above = _above_high(space)
        if above is not None:
            found.append(("above the high bound", above))
    elif isinstance(space, spaces.Discrete):
        start, n = int(space.start), int(space.n)
        found += [("above the range", start + n), ("below the range", start - 1), ("a float", start + 0.5)]
    elif isinstance(space, spaces.MultiDiscrete):
        found += [
            ("above the range", np.asarray(space.start + space.nvec, dtype=space.dtype)),
            ("an array of the wrong shape", np.zeros((*space.shape, 2), dtype=space.dtype)),
        ]
    elif isinstance(space, spaces.MultiBinary):
        found += [
            ("a 2", np.full(space.shape, 2, dtype=space.dtype)),
            ("an array of the wrong shape", np.zeros((*space.shape, 2), dtype=space.dtype)),
        ]
    return found


__all__ = ["invalid_actions", "neutral_action", "stacked_actions"]
