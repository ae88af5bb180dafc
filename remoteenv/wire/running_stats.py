"""Running statistics of timing samples (both processes use it).

The sim process keeps its pacing figures with :class:`RunningStats`; the
agent's :class:`remoteenv.agent.session.latency_stats.LatencyStats` is built from them.
Durations are in seconds unless a name says ``ticks``.
"""

from __future__ import annotations

import numpy as np

#: Samples kept for percentiles. Count, mean and max cover every sample.
DEFAULT_WINDOW = 10_000


class RunningStats:
    """Count, mean and max of every sample; p50/p99 over the last ``window`` samples.

    Memory is constant on long runs: the window is a ring buffer of float64
    allocated (and touched) up front.
    """

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        if window < 1:
            raise ValueError(f"window must be >= 1 sample, got {window}")
        self._ring = np.full(window, np.nan, dtype=np.float64)
        self.count = 0
        self.total = 0.0
        self.max = float("nan")

    @property
    def _recent(self) -> np.ndarray:
        return self._ring[: min(self.count, len(self._ring))]

    def add(self, value: float) -> None:
        value = float(value)
        self._ring[self.count % len(self._ring)] = value
        self.count += 1
        self.total += value
        if not value <= self.max:  # also true while max is nan
            self.max = value

    def clear(self) -> None:
        self._ring[:] = np.nan
        self.count = 0
        self.total = 0.0
        self.max = float("nan")

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else float("nan")

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100) of the recent window (nan when empty)."""
        if not self.count:
            return float("nan")
        return float(np.percentile(self._recent, q))

    def summary(self) -> dict[str, float | int]:
        """``{"count", "mean", "p50", "p99", "max"}`` as plain Python numbers."""
        if not self.count:
            nan = float("nan")
            return {"count": self.count, "mean": nan, "p50": nan, "p99": nan, "max": nan}
        p50, p99 = np.percentile(self._recent, [50, 99])
        return {"count": self.count, "mean": self.mean, "p50": float(p50), "p99": float(p99), "max": float(self.max)}
