"""BatchCheck accepts, returns and refuses exactly what check_actions does,
for the spaces and values a step may bring (NaN, infinities, bounds exactly,
other dtypes and shapes, per-element bounds)."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.wire.messages.action_rules import SMALL_BOX_ELEMENTS, BatchCheck, check_actions
from remoteenv.wire.wire_errors import InvalidAction

SPACES = [
    spaces.Box(-1.0, 1.0, (2,), np.float32),
    spaces.Box(np.array([-1.0, 0.0, -np.inf], np.float32), np.array([1.0, 2.5, np.inf], np.float32), dtype=np.float32),
    spaces.Box(-3.0, 3.0, (2, 2), np.float64),
    spaces.Box(0, 10, (3,), np.int64),
    spaces.Box(np.float32(0.1), np.float32(0.7), (1,), np.float32),
    spaces.Box(-np.inf, np.inf, (2,), np.float64),  # one pair of bounds, both infinite
    spaces.Discrete(4, start=1),
]


def _outcome(check, actions, n):
    try:
        out = check(actions, n)
    except InvalidAction as exc:
        return ("refused", str(exc))
    return ("accepted", type(out), getattr(out, "dtype", None), np.asarray(out).tolist())


def _candidates(space, n, rng):
    shape = (n, *space.shape)
    if isinstance(space, spaces.Discrete):
        yield rng.integers(0, 6, n)
        yield rng.integers(1, 5, n)
        return
    low = np.broadcast_to(space.low, space.shape)
    high = np.broadcast_to(space.high, space.shape)
    finite_low = np.where(np.isfinite(low), low, -1e6)
    finite_high = np.where(np.isfinite(high), high, 1e6)
    inside = rng.uniform(finite_low, finite_high, shape)
    yield inside.astype(space.dtype)
    yield inside  # float64 cast to the space's dtype
    yield np.broadcast_to(low, shape).astype(space.dtype)  # bounds exactly
    yield np.broadcast_to(high, shape).astype(space.dtype)
    for bad in (np.nan, np.inf, -np.inf, 1e9, -1e9):
        arr = inside.astype(np.float64).copy()
        arr.reshape(-1)[rng.integers(arr.size)] = bad
        yield arr
        yield arr.astype(np.float32)
    yield np.nextafter(np.broadcast_to(high, shape).astype(np.float32), np.float32(np.inf))
    both = inside.astype(np.float64).copy()  # inf and -inf together: their sum is NaN, yet no element is
    both.reshape(-1)[:2] = (np.inf, -np.inf) if both.size >= 2 else (np.inf,)
    yield both
    yield np.zeros(shape, np.bool_)
    yield np.zeros(shape, np.int8)
    yield np.zeros((n + 1, *space.shape), space.dtype)  # another shape
    yield np.zeros(shape, np.complex64)
    yield np.zeros(shape, object)
    yield inside.tolist()  # a list: check_actions checks it world by world


@pytest.mark.parametrize("space", SPACES, ids=str)
@pytest.mark.parametrize("n", [1, 3, 8, SMALL_BOX_ELEMENTS // 2 + 1, 4 * SMALL_BOX_ELEMENTS])
def test_batch_check_decides_as_check_actions(space, n):
    rng = np.random.default_rng(n)
    check = BatchCheck(space)
    for actions in _candidates(space, n, rng):
        assert _outcome(check, actions, n) == _outcome(lambda a, k: check_actions(space, a, k), actions, n), actions


def test_a_refusal_names_the_world_as_check_actions_does():
    space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    actions = np.zeros((4, 2), np.float32)
    actions[2, 1] = np.nan
    with pytest.raises(InvalidAction, match="of world 2 is outside"):
        BatchCheck(space)(actions, 4)
