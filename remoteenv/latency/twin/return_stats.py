"""Comparing two return distributions (real time and a twin, or any two paired runs).

The exact twin makes this unnecessary for a replay (its episodes are compared
step by step, :func:`remoteenv.latency.twin.compare_recorded`); it remains for
comparing runs that are not replays of each other, e.g. real time and a
lock-step run with a constant ``action_delay``.

Runs in the agent process.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: Default equivalence margin: the mean paired return difference must lie
#: within this fraction of the real-time mean return.
DEFAULT_RELATIVE_TOLERANCE = 0.10


def compare_returns(
    real_time: Sequence[float],
    replay: Sequence[float],
    *,
    relative_tolerance: float = DEFAULT_RELATIVE_TOLERANCE,
    confidence: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> dict[str, Any]:
    """Compare paired returns (episode ``e`` of both runs shares its reset
    seed and its latencies): an equivalence test of the means, and the
    distance between the two distributions.

    The percentile-bootstrap ``confidence`` interval of the mean paired
    difference ``replay - real_time`` (``resamples`` resamples of the
    episodes, from ``default_rng(seed)``) decides the ``verdict``:
    ``"equivalent"`` when it lies within ``+-tolerance``, where
    ``tolerance = relative_tolerance * mean(|real_time|)``; ``"different"``
    when it excludes 0; else ``"inconclusive"`` (too few episodes for the
    spread: run more). ``match`` is ``verdict == "equivalent"``. Also
    reported: how many pairs are equal, the largest difference, and the
    two-sample Kolmogorov-Smirnov distance of the two return distributions
    (with its p-value when scipy is installed; remoteenv does not need it)."""
    a = np.asarray(real_time, dtype=np.float64)
    b = np.asarray(replay, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1 or a.size < 2:
        raise ValueError(f"need two equal-length lists of >= 2 paired returns, got {a.shape} and {b.shape}")
    diff = b - a
    rng = np.random.default_rng(seed)
    means = diff[rng.integers(0, diff.size, size=(resamples, diff.size))].mean(axis=1)
    tail = (1.0 - confidence) / 2.0
    low, high = (float(q) for q in np.quantile(means, [tail, 1.0 - tail]))
    tolerance = relative_tolerance * float(np.abs(a).mean())
    if -tolerance <= low and high <= tolerance:
        verdict = "equivalent"
    elif low > 0 or high < 0:
        verdict = "different"
    else:
        verdict = "inconclusive"
    try:
        from scipy.stats import ks_2samp  # optional: remoteenv does not depend on scipy

        ks_pvalue: float | None = float(ks_2samp(a, b).pvalue)
    except ImportError:
        ks_pvalue = None
    return {
        "episodes": int(a.size),
        "real_time_mean": float(a.mean()),
        "replay_mean": float(b.mean()),
        "mean_difference": float(diff.mean()),
        "ci": [low, high],
        "confidence": confidence,
        "tolerance": tolerance,
        "relative_tolerance": relative_tolerance,
        "equal_pairs": int((diff == 0).sum()),
        "max_abs_difference": float(np.abs(diff).max()),
        "ks_distance": ks_distance(a, b),
        "ks_pvalue": ks_pvalue,
        "verdict": verdict,
        "match": verdict == "equivalent",
    }


def ks_distance(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """The two-sample Kolmogorov-Smirnov distance: the largest gap between the
    empirical distribution functions of ``a`` and ``b`` (0: the same sample
    distribution, 1: no overlap)."""
    x, y = np.sort(np.asarray(a, dtype=np.float64)), np.sort(np.asarray(b, dtype=np.float64))
    grid = np.union1d(x, y)
    return float(np.abs(np.searchsorted(x, grid, "right") / x.size - np.searchsorted(y, grid, "right") / y.size).max())


__all__ = ["DEFAULT_RELATIVE_TOLERANCE", "compare_returns", "ks_distance"]
