"""Running timing statistics: the agent's latency record of a real-time env.

Runs in the agent process (:class:`LatencyStats`, kept by
:class:`remoteenv.OpenAIRemoteEnv` as ``env.unwrapped.latency_stats``). The
sim process reuses :class:`RunningStats` for its pacing figures.

All durations are in seconds unless a name says ``ticks`` (control ticks of
``env.dt`` simulated seconds each).
"""

from __future__ import annotations

from typing import Any, Mapping

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
        return {"count": self.count, "mean": self.mean, "p50": float(p50), "p99": float(p99),
                "max": float(self.max)}


class LatencyStats:
    """What the agent saw of a real-time (or ``action_delay``) env, step by step.

    Fed by :meth:`record` with each step's ``info``; read the attributes or
    :meth:`summary`:

    latency_s, latency_ticks (:class:`RunningStats`)
        action latency: from the sim time of the observation the agent acted
        on to the sim time its action took effect. Steps whose action never
        took effect (the episode ended first) are not in these.
    round_trip_s (:class:`RunningStats`)
        wall-clock seconds from sending ``step`` to receiving its reply.
    late_actions (int)
        steps on which at least one whole control tick ran on the previous
        action (``info["late"]``): the agent did not keep up with the clock.
    never_applied (int)
        steps whose action never took effect because the episode terminated
        while the agent was thinking.
    pacing_overruns (int)
        substeps the sim process ran more than one substep behind its
        schedule (``info["pacing_overruns"]``, the sim's running count).
    steps (int)
        steps recorded.
    """

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        self.latency_s = RunningStats(window)
        self.latency_ticks = RunningStats(window)
        self.round_trip_s = RunningStats(window)
        self.late_actions = 0
        self.never_applied = 0
        self.pacing_overruns = 0
        self.steps = 0

    def record(self, info: Mapping[str, Any], round_trip_s: float | None = None) -> None:
        """Add one step: its ``info`` and the wall round trip measured by the caller."""
        self.steps += 1
        if round_trip_s is not None:
            self.round_trip_s.add(round_trip_s)
        if "latency_s" in info:
            if info["latency_s"] is None:
                self.never_applied += 1
            else:
                self.latency_s.add(info["latency_s"])
                self.latency_ticks.add(info["latency_ticks"])
        if info.get("late"):
            self.late_actions += 1
        overruns = info.get("pacing_overruns")
        if overruns is not None:
            self.pacing_overruns = max(self.pacing_overruns, int(overruns))

    def reset(self) -> None:
        """Forget everything recorded (the sim's overrun count is re-read on the next step)."""
        for stats in (self.latency_s, self.latency_ticks, self.round_trip_s):
            stats.clear()
        self.late_actions = self.never_applied = self.pacing_overruns = self.steps = 0

    def summary(self) -> dict[str, Any]:
        """All figures as a plain dict (seconds, ticks, counts)."""
        return {
            "steps": self.steps,
            "latency_s": self.latency_s.summary(),
            "latency_ticks": self.latency_ticks.summary(),
            "round_trip_s": self.round_trip_s.summary(),
            "late_actions": self.late_actions,
            "never_applied": self.never_applied,
            "pacing_overruns": self.pacing_overruns,
        }

    def format(self) -> str:
        """A few human-readable lines (milliseconds and ticks)."""

        def ms(s: dict[str, float | int]) -> str:
            return (f"mean {1e3 * s['mean']:.2f}  p50 {1e3 * s['p50']:.2f}  "
                    f"p99 {1e3 * s['p99']:.2f}  max {1e3 * s['max']:.2f} ms")

        t = self.latency_ticks.summary()
        return "\n".join([
            f"steps {self.steps}",
            f"action latency    {ms(self.latency_s.summary())} (sim time)",
            f"                  mean {t['mean']:.2f}  p50 {t['p50']:.2f}  p99 {t['p99']:.2f}  "
            f"max {t['max']:.2f} ticks",
            f"wall round trip   {ms(self.round_trip_s.summary())}",
            f"late actions {self.late_actions}  never applied {self.never_applied}  "
            f"pacing overruns {self.pacing_overruns}",
        ])

    def __repr__(self) -> str:
        return f"LatencyStats({self.summary()!r})"
