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

from remoteenv.wire.running_stats import DEFAULT_WINDOW, RunningStats

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
        took effect (the episode ended first) are not in these. In delayed
        lock-step, the latency of the action in force during each tick
        (known once it arrived; steps on the default action are not in these).
    action_age_ticks (:class:`RunningStats`)
        delayed lock-step: the age of the action in force during each tick
        (``info["action_delay_ticks"]``).
    actions_sent, actions_acted (int)
        delayed lock-step: actions sent, and those that came into force
        (``info["action_took_effect"]``); :attr:`never_acted_fraction` is
        ``1 - acted / sent`` (overtaken actions, and those in flight when
        their episode ended).
    round_trip_s (:class:`RunningStats`)
        wall-clock seconds from sending ``step`` to receiving its reply.
    late_actions (int)
        steps on which at least one whole control tick ran on the previous
        action (``info["late"]``): the agent did not keep up with the clock.
    never_applied (int)
        real time: steps whose action never took effect because the episode
        terminated while the agent was thinking.
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
        self.action_age_ticks = RunningStats(window)
        self.actions_sent = 0
        self.actions_acted = 0
        self.late_actions = 0
        self.never_applied = 0
        self.pacing_overruns = 0
        self.steps = 0

    def record(self, info: Mapping[str, Any], round_trip_s: float | None = None) -> None:
        """Add one step: its ``info`` and the wall round trip measured by the caller."""
        self.steps += 1
        if round_trip_s is not None:
            self.round_trip_s.add(round_trip_s)
        lock_step = "action_delay_ticks" in info
        if lock_step:
            self._record_lock_step(info.get("action_delay_ticks"), info.get("action_took_effect"))
        if "latency_s" in info:
            if info["latency_s"] is None:
                self.never_applied += 0 if lock_step else 1
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
        ages: Any = infos.get("action_delay_ticks")
        lock_step = ages is not None
        if lock_step:
            took: Any = infos.get("action_took_effect")
            took_mask: Any = infos.get("_action_took_effect")
            for i in np.flatnonzero(infos["_action_delay_ticks"]):
                self._record_lock_step(
                    ages[i], took[i] if took is not None and took_mask is not None and took_mask[i] else None
                )
        latency = infos.get("latency_s")
        if latency is not None:
            ticks = infos.get("latency_ticks")
            for i in np.flatnonzero(infos["_latency_s"]):
                if latency[i] is None or latency[i] != latency[i]:  # None, or NaN where a column filled it
                    self.never_applied += 0 if lock_step else 1
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

    def _record_lock_step(self, age: Any, took_effect: Any) -> None:
        """One world's tick of delayed lock-step: the age of its action in force, and whether it just arrived."""
        if _real(age):
            self.action_age_ticks.add(age)
        self.actions_sent += 1
        if took_effect is True or took_effect is np.True_:
            self.actions_acted += 1

    @property
    def never_acted_fraction(self) -> float | None:
        """Delayed lock-step: the fraction of the actions sent that never took effect (None before any)."""
        return 1.0 - self.actions_acted / self.actions_sent if self.actions_sent else None

    def reset(self) -> None:
        """Forget everything recorded (the sim's overrun count is re-read on the next step)."""
        for stats in (self.latency_s, self.latency_ticks, self.round_trip_s, self.action_age_ticks):
            stats.clear()
        self.late_actions = self.never_applied = self.pacing_overruns = self.steps = 0
        self.actions_sent = self.actions_acted = 0

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
            "action_age_ticks": self.action_age_ticks.summary(),
            "actions_sent": self.actions_sent,
            "actions_acted": self.actions_acted,
            "never_acted_fraction": self.never_acted_fraction,
        }

    def format(self) -> str:
        """A few human-readable lines (milliseconds and ticks)."""

        def ms(s: dict[str, float | int]) -> str:
            return (
                f"mean {1e3 * s['mean']:.2f}  p50 {1e3 * s['p50']:.2f}  "
                f"p99 {1e3 * s['p99']:.2f}  max {1e3 * s['max']:.2f} ms"
            )

        t = self.latency_ticks.summary()
        lock_step = []
        if self.actions_sent:
            lock_step = [
                f"action in force   mean age {self.action_age_ticks.summary()['mean']:.2f} ticks  "
                f"never acted {self.never_acted_fraction:.3f} of {self.actions_sent} actions"
            ]
        return "\n".join(
            [
                *lock_step,
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
