"""Observations checked against the declared space where the scene produces them.

Runs in the sim process. :class:`BaseEnv` calls :func:`check_observation` on
what ``reset_model`` and ``post_step`` return, so a scene that returns float64
for a float32 space, or a shape other than the declared one, fails at once
with a message naming the scene, the hook, the space and what came back,
instead of passing silently (single env) or surfacing as a numpy error in the
agent's vector env. The check is cheap (a dtype and a shape per array);
bounds are checked only when asked (``BaseEnv.check_obs_bounds``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.wire.wire_errors import short_repr


class ObservationError(TypeError):
    """A scene hook returned an observation that does not fit its declared space."""


def _describe(obs: Any) -> str:
    if isinstance(obs, np.ndarray):
        return f"an array of dtype {obs.dtype} and shape {obs.shape}"
    return f"a {type(obs).__name__} {short_repr(obs, 80)}"


#: Spaces whose observation is one numpy array of the space's dtype and shape.
_ARRAY_SPACES = (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)


def _problem(space: spaces.Space, obs: Any, bounds: bool) -> str | None:
    """What is wrong with ``obs`` for ``space`` (None if it fits)."""
    if isinstance(space, _ARRAY_SPACES):
        if not isinstance(obs, np.ndarray):
            return f"got {_describe(obs)}, not a numpy array"
        if obs.dtype != space.dtype or obs.shape != space.shape:
            return f"got {_describe(obs)}, expected dtype {space.dtype} and shape {space.shape}"
    elif isinstance(space, spaces.Discrete):
        if not isinstance(obs, (int, np.integer)) or isinstance(obs, (bool, np.bool_)):
            return f"got {_describe(obs)}, expected an int"
    elif isinstance(space, spaces.Dict):
        if not isinstance(obs, dict) or set(obs) != set(space.spaces):
            return f"got {_describe(obs)}, expected a dict with keys {sorted(space.spaces)}"
        for key, sub in space.spaces.items():
            problem = _problem(sub, obs[key], bounds)
            if problem is not None:
                return f"[{key!r}]: {problem}"
        return None
    elif isinstance(space, spaces.Tuple):
        if not isinstance(obs, (tuple, list)) or len(obs) != len(space.spaces):
            return f"got {_describe(obs)}, expected a tuple of {len(space.spaces)}"
        for i, (sub, item) in enumerate(zip(space.spaces, obs)):
            problem = _problem(sub, item, bounds)
            if problem is not None:
                return f"[{i}]: {problem}"
        return None
    if bounds and not space.contains(obs):
        return f"got {_describe(obs)} outside the space's bounds"
    return None


def check_observation(space: spaces.Space, obs: Any, *, scene: str, hook: str, bounds: bool = False) -> None:
    """Raise :class:`ObservationError` unless ``obs`` fits ``space``: dtype and
    shape always (every array of a Dict/Tuple space), bounds when ``bounds``.
    ``scene`` and ``hook`` (e.g. ``"post_step"``) name the culprit."""
    problem = _problem(space, obs, bounds)
    if problem is not None:
        raise ObservationError(
            f"{scene}.{hook} returned an observation that does not fit observation_space {space}: "
            f"{problem}; return exactly the declared dtype and shape (e.g. np.asarray(obs, dtype=...))"
        )


def rows_fit(space: spaces.Space, rows: np.ndarray) -> bool:
    """Whether every row of the stacked observations ``rows`` fits ``space`` as
    :func:`check_observation` checks it without bounds: the dtype and shape of an
    array space, read once off the stack (False: check the rows one by one)."""
    return isinstance(space, _ARRAY_SPACES) and rows.dtype == space.dtype and rows.shape[1:] == space.shape


__all__ = ["ObservationError", "check_observation", "rows_fit"]
