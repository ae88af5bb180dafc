"""The arguments of a vector ``reset``: one seed per world and the reset mask.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`); pure functions.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from remoteenv.agent.errors import StateError
from remoteenv.wire.wire_errors import short_repr


def is_int_seed(seed: Any) -> bool:
    """True for a Python or numpy integer (not a bool): one seed for the whole vector."""
    return isinstance(seed, (int, np.integer)) and not isinstance(seed, bool)


def world_seeds(seed: int | Sequence[int | None] | None, num_envs: int) -> list[int | None]:
    """The seed of each world: None for all, ``seed + i`` for world ``i`` of an
    int seed, or a list's entries (one per world, each an int or None)."""
    if seed is None:
        return [None] * num_envs
    if is_int_seed(seed):
        return [int(seed) + i for i in range(num_envs)]  # type: ignore[arg-type]
    seeds = [None if s is None else int(s) for s in seed]  # type: ignore[union-attr]
    if len(seeds) != num_envs:
        raise ValueError(f"a list of seeds needs one per world: {num_envs}, got {len(seeds)}")
    return seeds


def split_reset_mask(
    options: dict[str, Any] | None, num_envs: int, first_reset: bool
) -> tuple[dict[str, Any] | None, np.ndarray]:
    """``(options without "reset_mask", mask)``: which worlds a reset resets
    (all unless ``options["reset_mask"]`` says; it must be a numpy bool array
    of ``num_envs`` selecting at least one, and all on the ``first_reset``)."""
    options = dict(options) if options is not None else None
    mask = np.ones(num_envs, dtype=np.bool_)
    if options is not None and "reset_mask" in options:
        mask = options.pop("reset_mask")
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (num_envs,):
            raise TypeError(
                f"options['reset_mask'] must be a numpy bool array of shape ({num_envs},), got {short_repr(mask)}"
            )
        if not mask.any():
            raise ValueError("options['reset_mask'] must select at least one world")
        if first_reset and not mask.all():
            raise StateError("the first reset must reset every world; drop reset_mask")
    return options, mask


__all__ = ["is_int_seed", "split_reset_mask", "world_seeds"]
