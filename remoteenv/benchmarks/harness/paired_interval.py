"""How sure one run of alternating rounds is of a ratio: the paired rounds' mean and its interval.

Benchmarks only (``bench --train-loop``). A round runs every contender once,
one after the other, so each round gives one ratio of two rates that met the
same host. On a noisy host those ratios spread widely (0.8-1.2 within one
run here), and a ratio of medians can land on either side of a target by
chance. :func:`paired_interval` summarises the rounds' ratios by their
geometric mean (the mean of their logarithms, so 0.9 and 1.1 do not average
above 1) and a percentile bootstrap interval of it: the rounds are resampled
with replacement, a fixed number of times with a fixed seed, so the same
rounds always give the same interval. :func:`settled` reads a target
against it: met when the whole interval is at or above the target, missed
when it is wholly below, otherwise the run cannot tell (more rounds narrow
the interval). With few rounds a percentile bootstrap is somewhat too
narrow; below :data:`MIN_ROUNDS` no interval is given at all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Fewest paired rounds an interval is given for.
MIN_ROUNDS = 5
#: Bootstrap resamples of the rounds.
RESAMPLES = 10_000
#: The interval's coverage.
CONFIDENCE = 0.95


def paired_interval(ratios: Sequence[float], seed: int = 0) -> tuple[float, float, float] | None:
    """``(geometric mean, low, high)`` of the rounds' ``ratios`` (each > 0):
    the mean and its :data:`CONFIDENCE` percentile bootstrap interval over
    :data:`RESAMPLES` resamples drawn with ``seed``; None with fewer than
    :data:`MIN_ROUNDS` ratios or any ratio not a positive finite number."""
    values = np.asarray(ratios, dtype=np.float64)
    if values.ndim != 1 or len(values) < MIN_ROUNDS or not (np.isfinite(values).all() and (values > 0).all()):
        return None
    logs = np.log(values)
    picks = np.random.default_rng(seed).integers(0, len(logs), size=(RESAMPLES, len(logs)))
    tail = (1.0 - CONFIDENCE) / 2 * 100
    low, high = np.percentile(logs[picks].mean(axis=1), [tail, 100 - tail])
    return math.exp(logs.mean()), math.exp(low), math.exp(high)


def settled(interval: tuple[float, float, float], target: float) -> str:
    """What ``interval`` (:func:`paired_interval`'s) says of ``target``:
    ``"met"`` (wholly at or above it), ``"missed"`` (wholly below) or
    ``"not settled"`` (it straddles the target: this run cannot tell)."""
    _, low, high = interval
    if low >= target:
        return "met"
    if high < target:
        return "missed"
    return "not settled"


__all__ = ["CONFIDENCE", "MIN_ROUNDS", "RESAMPLES", "paired_interval", "settled"]
