"""The agent's latency record of a real-time (or ``action_delay``) env.

Runs in the agent process (:class:`LatencyStats`, kept by
:class:`remoteenv.OpenAIRemoteEnv` and :class:`remoteenv.RemoteVectorEnv` as
``env.unwrapped.latency_stats``).

All durations are in seconds unless a name says ``ticks`` (control ticks of
``env.dt`` simulated seconds each).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from remoteenv.wire.stats import DEFAULT_WINDOW, RunningStats

__all__ = ["DEFAULT_WINDOW", "LatencyStats", "RunningStats"]


def _real(value: Any) -> bool:
    """A finite-or-not real number (not a bool, not a string): what the stats may record.
    The info values come from the sim: anything else is skipped, not recorded."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


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
            elif _real(info["latency_s"]):
                self.latency_s.add(info["latency_s"])
                if _real(info.get("latency_ticks")):
                    self.latency_ticks.add(info["latency_ticks"])
        if info.get("late") is True:
            self.late_actions += 1
        overruns: Any = info.get("pacing_overruns")
        if _real(overruns):
            self.pacing_overruns = max(self.pacing_overruns, int(overruns))

    def record_vector(self, infos: Mapping[str, Any], round_trip_s: float | None = None) -> None:
        """Add one vector step: its Gymnasium vector ``infos`` (each key an array
        over the worlds, ``_key`` saying which worlds have it) and the wall round
        trip of the whole call. Counts one step and one round trip per call, and
        one latency sample per world that reported one."""
        self.steps += 1
        if round_trip_s is not None:
            self.round_trip_s.add(round_trip_s)
        latency = infos.get("latency_s")
        if latency is not None:
            ticks = infos.get("latency_ticks")
            for i in np.flatnonzero(infos["_latency_s"]):
                if latency[i] is None or latency[i] != latency[i]:  # None, or NaN where a column filled it
                    self.never_applied += 1
                elif _real(latency[i]):
                    self.latency_s.add(latency[i])
                    if ticks is not None and _real(ticks[i]):
                        self.latency_ticks.add(ticks[i])
        late = infos.get("late")
        if late is not None:
            flags = [late[i] for i in np.flatnonzero(infos["_late"])]
            self.late_actions += sum(1 for flag in flags if flag is True or flag is np.True_)
        overruns = infos.get("pacing_overruns")
        if overruns is not None:
            counts = [overruns[i] for i in np.flatnonzero(infos["_pacing_overruns"])]
            counts = [int(c) for c in counts if _real(c)]
            if counts:
                self.pacing_overruns = max(self.pacing_overruns, max(counts))

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
            return (
                f"mean {1e3 * s['mean']:.2f}  p50 {1e3 * s['p50']:.2f}  "
                f"p99 {1e3 * s['p99']:.2f}  max {1e3 * s['max']:.2f} ms"
            )

        t = self.latency_ticks.summary()
        return "\n".join(
            [
                f"steps {self.steps}",
                f"action latency    {ms(self.latency_s.summary())} (sim time)",
                f"                  mean {t['mean']:.2f}  p50 {t['p50']:.2f}  p99 {t['p99']:.2f}  "
                f"max {t['max']:.2f} ticks",
                f"wall round trip   {ms(self.round_trip_s.summary())}",
                f"late actions {self.late_actions}  never applied {self.never_applied}  "
                f"pacing overruns {self.pacing_overruns}",
            ]
        )

    def __repr__(self) -> str:
        return f"LatencyStats({self.summary()!r})"
