"""The twin's trace: per-tick countdowns, one per real-time step (see :mod:`remoteenv.latency.twin`). Runs in the agent process."""

from __future__ import annotations

import os
from collections.abc import Sequence

from remoteenv.wire.delays.delay_specs import MAX_DELAY_TICKS, MAX_VALUES
from remoteenv.wire.files.safe_writes import write_user_file

#: How a real-time latency becomes whole ticks: ``"nearest"`` (the tick boundary
#: nearest to the substep where the action took effect; halves go up) or
#: ``"floor"`` (the boundary before it: the reply structure's own figure).
ROUNDINGS = ("nearest", "floor")


def twin_latency(ticks_elapsed: int, latency_ticks: float | None, rounding: str = "nearest") -> int:
    """The twin's whole-tick latency of one real-time step.

    ``ticks_elapsed`` and ``latency_ticks`` are the step's ``info`` values
    (``latency_ticks`` None: the action never took effect, the episode ended
    first; the twin's latency is then ``ticks_elapsed``, due one tick after
    the end). Otherwise ``m = ticks_elapsed - 1 = floor(latency_ticks)``;
    ``"floor"`` gives ``m``, ``"nearest"`` gives ``m + 1`` when the action
    took effect in the second half of its tick (``latency_ticks - m >= 0.5``).
    """
    if isinstance(ticks_elapsed, bool) or not isinstance(ticks_elapsed, int) or ticks_elapsed < 1:
        raise ValueError(f"a real-time step spans at least one tick, got ticks_elapsed={ticks_elapsed!r}")
    if rounding not in ROUNDINGS:
        raise ValueError(f"rounding must be one of {ROUNDINGS}, got {rounding!r}")
    if latency_ticks is None:
        return ticks_elapsed
    m = ticks_elapsed - 1
    if rounding == "nearest" and float(latency_ticks) - m >= 0.5 - 1e-6:  # 1e-6: sim times are sums of floats
        return m + 1
    return m


def twin_values(
    ticks_elapsed: Sequence[int], latency_ticks: Sequence[float | None], rounding: str = "nearest"
) -> list[int]:
    """The twin's trace of one episode: for each real-time step the countdown
    ``L, L - 1, ...`` of its ``ticks_elapsed`` values, ``L`` its
    :func:`twin_latency`: one action delay per tick, every copy of the step's
    action due at the same tick.

    A countdown that ends at 1 (its action due the tick after its step)
    followed by one that starts at 0 (the next action due that same tick,
    which overtakes it) would read as one longer countdown; the first is then
    raised by one tick, which changes nothing (its action is overtaken either
    way) and keeps every step's countdown readable from the values alone
    (:func:`decision_ticks`)."""
    if len(ticks_elapsed) != len(latency_ticks):
        raise ValueError(f"one latency per step: {len(ticks_elapsed)} steps, {len(latency_ticks)} latencies")
    values: list[int] = []
    start = 0
    for ticks, latency in zip(ticks_elapsed, latency_ticks):
        top = twin_latency(ticks, latency, rounding)
        if top > MAX_DELAY_TICKS - 1:
            raise ValueError(f"a real-time step spanned {ticks} ticks, more than a twin can replay")
        if values and values[-1] == 1 and top == 0:
            values[start:] = [v + 1 for v in values[start:]]
        start = len(values)
        values += range(top, top - ticks, -1)
    return values


def decision_ticks(values: Sequence[float]) -> list[int]:
    """How many lock-step ticks each recorded step is held: the lengths of
    the runs of ``values`` that count down by one (see :func:`twin_values`).
    Any sequence of delays splits into such runs."""
    holds: list[int] = []
    run = 0
    for i, v in enumerate(values):
        if run and int(v) == int(values[i - 1]) - 1:
            run += 1
        else:
            if run:
                holds.append(run)
            run = 1
    if run:
        holds.append(run)
    return holds


def write_trace_file(path: str | os.PathLike[str], values: Sequence[int], header: Sequence[str] = ()) -> str:
    """Write ``values`` as a text trace that :class:`remoteenv.delays.Trace` loads:
    ``#`` comment lines from ``header``, then one line per countdown (per real-time step). Written
    atomically (never through a symlink at ``path``), mode 0644. Returns the path."""
    if not 1 <= len(values) <= MAX_VALUES:
        raise ValueError(f"a trace holds 1..{MAX_VALUES} values, this episode has {len(values)}")
    holds = decision_ticks(values)
    lines = [f"# {line}" for line in header]
    i = 0
    for hold in holds:
        lines.append(" ".join(str(int(v)) for v in values[i : i + hold]))
        i += hold
    path = os.fspath(path)
    write_user_file(path, "\n".join(lines) + "\n", "trace")
    return path


__all__ = ["ROUNDINGS", "decision_ticks", "twin_latency", "twin_values", "write_trace_file"]
