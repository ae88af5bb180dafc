"""Autoreset planning of a vector env: pure functions over per-world arrays.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`). Before a
vector step, :func:`plan_ops` says what each world does (a ``step_batch``
op, see :mod:`remoteenv.wire.protocol`); after it, :func:`after_step` applies
the time limit and says which worlds must be reset next; :func:`after_reset`
clears the worlds a reset started afresh. The semantics are Gymnasium's
:class:`~gymnasium.vector.AutoresetMode`:

- ``NEXT_STEP``: the step after an episode ends resets that world (its
  action ignored; reward 0, not terminated, not truncated).
- ``SAME_STEP``: the step that ends an episode also resets the world; the
  sim reports the ended episode's last obs and info as final.
- ``DISABLED``: the caller resets ended worlds with a masked ``reset``;
  stepping one before that is an error.

``elapsed`` counts the steps of each world's current episode;
``max_episode_steps`` (None: no limit) truncates an episode at that count.
"""

from __future__ import annotations

import functools

import numpy as np
from gymnasium.vector import AutoresetMode

from remoteenv.agent.errors import StateError
from remoteenv.wire.protocol import OP_RESET, OP_STEP, OP_STEP_AUTORESET, OP_STEP_RESET


def plan_ops(
    mode: AutoresetMode,
    needs_reset: np.ndarray,
    elapsed: np.ndarray,
    max_episode_steps: int | None,
) -> np.ndarray:
    """The op of each world for the next step.

    Args:
        mode: the autoreset mode.
        needs_reset: bool per world: its episode ended at the last step (never
            set in ``SAME_STEP``, where ended worlds are reset at once).
        elapsed: steps of each world's current episode so far.
        max_episode_steps: the time limit, or None.

    Raises:
        remoteenv.StateError: (a ``RuntimeError``) in ``DISABLED`` mode, if a
            world ended and was not reset.
    """
    n = len(needs_reset)
    if mode == AutoresetMode.NEXT_STEP:
        if not _any(needs_reset):
            return _every_world_steps(n)
        return np.where(needs_reset, OP_RESET, OP_STEP)
    if mode == AutoresetMode.SAME_STEP:
        ops = np.full(n, OP_STEP_AUTORESET)
        if max_episode_steps is not None:
            ops[elapsed + 1 >= max_episode_steps] = OP_STEP_RESET
        return ops
    if needs_reset.any():
        ended = np.flatnonzero(needs_reset).tolist()
        raise StateError(
            f"worlds {ended} ended at the last step and autoreset_mode is DISABLED: reset "
            "them with reset(options={'reset_mask': mask}) before stepping again"
        )
    return np.full(n, OP_STEP)


def _any(flags: np.ndarray) -> bool:
    """Whether any of the bools ``flags`` is set: for a few worlds as Python
    bools (a numpy reduction is the slowest call of a step right after the
    caller's own numpy or torch work), else numpy's."""
    return True in flags.tolist() if len(flags) <= 64 else bool(flags.any())


@functools.lru_cache(maxsize=64)
def _every_world_steps(n: int) -> np.ndarray:
    """Read-only ops of ``n`` worlds that all step: the common plan, made once per ``n``."""
    ops = np.full(n, OP_STEP, dtype=np.int64)
    ops.setflags(write=False)
    return ops


def after_step(
    mode: AutoresetMode,
    ops: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    elapsed: np.ndarray,
    max_episode_steps: int | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Book a step whose ops were ``ops`` and whose sims reported ``terminated``
    and ``truncated``. Returns ``(truncated, elapsed, needs_reset)``: the flags
    with the time limit applied, the new step counts, and which worlds the
    next step must reset. The inputs are not modified."""
    if ops is _every_world_steps(len(ops)):  # plan_ops's plan where every world steps
        elapsed = elapsed + 1
        if max_episode_steps is not None:
            truncated = truncated | (elapsed >= max_episode_steps)
    else:
        stepped = ops != OP_RESET
        elapsed = np.where(stepped, elapsed + 1, 0)
        if max_episode_steps is not None:
            truncated = truncated | (stepped & (elapsed >= max_episode_steps))
    ended = terminated | truncated
    if mode == AutoresetMode.SAME_STEP:
        elapsed[ended] = 0
        return truncated, elapsed, np.zeros(len(ops), dtype=np.bool_)
    return truncated, elapsed, ended


def after_reset(mask: np.ndarray, elapsed: np.ndarray, needs_reset: np.ndarray) -> None:
    """Start the episodes of the worlds in ``mask`` afresh (in place)."""
    elapsed[mask] = 0
    needs_reset[mask] = False


__all__ = ["after_reset", "after_step", "plan_ops"]
