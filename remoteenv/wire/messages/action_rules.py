"""Action checks, one set of rules for both processes.

The agent checks an action before sending it (a clear ``ValueError`` naming
the space, no round trip); the sim checks it again on arrival, because any
client may send anything. Both call these functions, so a value is accepted
on one side exactly when it is accepted on the other.

Rules:

- Box: a numeric (bool, int, unsigned, float) array-like of the space's
  shape; cast to the space's dtype; every element within ``[low, high]``
  (NaN never is).
- Discrete: a Python or numpy integer (a 0-d integer array counts), never a
  bool; within ``[start, start + n)``. Returned as a Python ``int``.
- Other spaces: a numpy array is first cast to the space's dtype when numpy
  calls that cast "same kind"; then ``space.contains`` decides.

Each check raises :class:`~remoteenv.wire.wire_errors.InvalidAction` (a
``ValueError``) whose message names the space and the (shortened) value.
:class:`BatchCheck` is :func:`check_actions` for one space, for the hot path
of every step: it accepts and returns exactly what that function does.
"""

from __future__ import annotations

from itertools import cycle
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.wire.wire_errors import InvalidAction, short_repr

#: The smallest and largest element of an array, NaN if it holds one (numpy's reductions propagate NaN).
_smallest, _largest = np.minimum.reduce, np.maximum.reduce


def check_action(space: spaces.Space, action: Any, where: str = "") -> Any:
    """``action`` in its canonical form for ``space``; raises :class:`InvalidAction`.

    ``where`` prefixes the message (e.g. ``"world 3: "``).
    """
    if isinstance(space, spaces.Box):
        try:
            arr = np.asarray(action)
        except Exception as exc:  # ragged lists and the like
            raise InvalidAction(f"{where}action {short_repr(action)} does not fit {space}: {exc}") from None
        if arr.dtype.kind not in "biuf":
            raise InvalidAction(f"{where}action {short_repr(action)} of dtype {arr.dtype} does not fit {space}")
        arr = arr.astype(space.dtype, copy=False)
        if arr.shape != space.shape:
            raise InvalidAction(f"{where}action of shape {arr.shape} does not fit {space}: {short_repr(action)}")
        if not ((arr >= space.low).all() and (arr <= space.high).all()):
            if arr.dtype.kind == "f" and np.isnan(arr).any():
                raise InvalidAction(f"{where}action {short_repr(action)} contains NaN; space {space}")
            raise InvalidAction(f"{where}action {short_repr(action)} is outside {space}")
        return arr
    if isinstance(space, spaces.Discrete):
        if isinstance(action, np.ndarray) and action.shape == ():
            action = action.item()
        if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
            raise InvalidAction(f"{where}action {short_repr(action)} is not an int of {space}")
        value = int(action)
        if not space.start <= value < space.start + space.n:
            raise InvalidAction(f"{where}action {value} is outside {space}")
        return value
    try:
        dtype = getattr(space, "dtype", None)
        if isinstance(action, np.ndarray) and dtype is not None and action.dtype != dtype:
            if not np.can_cast(action.dtype, dtype, casting="same_kind"):
                raise InvalidAction(f"{where}action of dtype {action.dtype} does not fit {space}")
            action = action.astype(dtype)
        inside = space.contains(action)
    except InvalidAction:
        raise
    except Exception as exc:
        raise InvalidAction(f"{where}action {short_repr(action)} does not fit {space}: {exc}") from None
    if not inside:
        raise InvalidAction(f"{where}action {short_repr(action)} is not in {space}")
    return action


def check_actions(space: spaces.Space, actions: Any, n: int) -> Any:
    """The actions of ``n`` worlds, checked; indexable by world.

    Box: one array of shape ``(n, *space.shape)`` (returned as such, cast to
    the space's dtype). Discrete: an integer array of shape ``(n,)``
    (returned as an int64 array). Otherwise (or for a list): a sequence of
    ``n`` actions, each checked with :func:`check_action`. Messages name the
    first world whose action is out of the space.
    """
    if isinstance(space, spaces.Box) and isinstance(actions, np.ndarray):
        if actions.dtype.kind not in "biuf" or actions.shape != (n, *space.shape):
            raise InvalidAction(
                f"actions of shape {actions.shape} and dtype {actions.dtype} do not fit {n} worlds of {space}"
            )
        arr = actions.astype(space.dtype, copy=False)
        inside = (arr >= space.low) & (arr <= space.high)  # NaN compares False
        if not inside.all():
            bad = int(np.flatnonzero(~inside.reshape(n, -1).all(axis=1))[0])
            raise InvalidAction(f"action {short_repr(arr[bad])} of world {bad} is outside {space}")
        return arr
    if isinstance(space, spaces.Discrete) and isinstance(actions, np.ndarray) and actions.dtype.kind in "iu":
        if actions.shape != (n,):
            raise InvalidAction(f"actions of shape {actions.shape} do not fit {n} worlds of {space}")
        start = int(space.start)
        inside = (actions >= start) & (actions < start + int(space.n))
        if not inside.all():
            bad = int(np.flatnonzero(~inside)[0])
            raise InvalidAction(f"action {actions[bad]} of world {bad} is outside {space}")
        return actions.astype(np.int64, copy=False)
    if not isinstance(actions, (list, tuple)) or len(actions) != n:
        raise InvalidAction(f"actions must be an array or list with one action per world ({n})")
    return [check_action(space, a, where=f"world {w}: ") for w, a in enumerate(actions)]


#: Elements of a Box batch up to which :class:`BatchCheck` compares Python
#: numbers: a few calls, where numpy's comparisons and reductions are several
#: calls of a much larger code path (slow right after the process woke up).
SMALL_BOX_ELEMENTS = 64


class BatchCheck:
    """:func:`check_actions` for ``space``, its bounds read once: ``check(actions, n)``
    accepts, returns and refuses exactly what ``check_actions(space, actions, n)`` does.

    A numeric array of a small Box batch (at most :data:`SMALL_BOX_ELEMENTS`
    elements) is compared as Python numbers (exact: a value of the space's
    dtype widens to a Python float or int without rounding): with one pair of
    bounds for every element, its smallest and largest element, trusted when
    the elements' sum is a number (no NaN among them); with bounds per
    element, element by element (NaN compares False). A larger one whose elements all share
    one pair of bounds (the usual Box) is accepted on its smallest and
    largest element, two reductions (numpy's minimum and maximum propagate
    NaN, which compares False). Anything else, and every refusal with its
    message, is :func:`check_actions`'s.
    """

    def __init__(self, space: spaces.Space) -> None:
        self.space = space
        self._box = isinstance(space, spaces.Box)
        self._shape: tuple[int, ...] = ()
        self._dtype: np.dtype | None = None
        self._lows: list[Any] = []
        self._highs: list[Any] = []
        #: One bound for every element (the usual Box), else None: then per element.
        self._uniform: tuple[Any, Any] | None = None
        if isinstance(space, spaces.Box):
            self._shape, self._dtype = space.shape, space.dtype
            self._lows, self._highs = space.low.reshape(-1).tolist(), space.high.reshape(-1).tolist()
            if self._lows and len(set(self._lows)) == 1 and len(set(self._highs)) == 1:
                self._uniform = (self._lows[0], self._highs[0])

    def __call__(self, actions: Any, n: int) -> Any:
        if (
            self._box
            and type(actions) is np.ndarray
            and actions.dtype.kind in "biuf"
            and actions.shape == (n, *self._shape)
        ):
            arr = actions.astype(self._dtype, copy=False)
            uniform = self._uniform
            if actions.size <= SMALL_BOX_ELEMENTS:
                values = arr.reshape(-1).tolist()
                if uniform is not None:
                    # min and max are exact unless a NaN is there, and then the sum is NaN
                    # (or where inf meets -inf: the exact check below decides).
                    total = sum(values)
                    inside = total == total and uniform[0] <= min(values) and max(values) <= uniform[1]
                else:
                    inside = all(lo <= v <= hi for v, lo, hi in zip(values, cycle(self._lows), cycle(self._highs)))
                if inside:
                    return arr
            elif uniform is not None:
                flat = arr.reshape(-1)
                if uniform[0] <= _smallest(flat) and _largest(flat) <= uniform[1]:
                    return arr
        return check_actions(self.space, actions, n)
