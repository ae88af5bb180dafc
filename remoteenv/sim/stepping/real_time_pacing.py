"""The pacing figures of one real-time world: how late its substeps ran.

Runs in the sim process. :class:`~remoteenv.sim.stepping.real_time_world.RealTimeStepper`
is one of these: it records every substep boundary's lateness and every
action's wait here, and the ``timing`` command reports them
(:meth:`PacingFigures.timing`, all in wall seconds).
"""

from __future__ import annotations

from typing import Any

from remoteenv.wire.running_stats import RunningStats

#: Wall seconds a world may fall behind its deadlines and still catch up
#: (run the missed substeps back to back). A boundary processed later than
#: this *slips* the clock instead: its deadline becomes the moment it is
#: processed and every later one moves with it, so a sim that cannot keep
#: pace at all (an impossible ``real_time_factor``, a stall of seconds)
#: still applies the actions it reads, never at a deadline before their
#: arrival. The wall time slipped is not simulated.
CATCH_UP_LIMIT_S = 1.0


class PacingFigures:
    """Wall-clock figures of a world whose substeps are ``period`` wall seconds apart.

    ``link_delay`` holds the emulated link's draws (wall seconds), reported beside.
    """

    def __init__(self, period: float, link_delay: RunningStats) -> None:
        #: Wall seconds per physics substep.
        self.period = float(period)
        #: Wall-clock lateness (s) of every substep boundary against its deadline;
        #: percentiles over the last 60 s of substeps (at most 200,000 of them).
        self.pacing_error = RunningStats(window=min(200_000, max(1000, int(60.0 / self.period))))
        #: Wall seconds from a step request's arrival to the substep where it took effect.
        self.apply_delay = RunningStats()
        #: Substeps run more than one ``period`` late, since the process started.
        self.overruns = 0
        #: Substeps run, since the process started (or the last :meth:`clear_timing`).
        self.substeps = 0
        #: Emulated link delays drawn (wall seconds).
        self.link_delay = link_delay
        #: Times the clock slipped (see :data:`CATCH_UP_LIMIT_S`), and the wall seconds it dropped.
        self.slips = 0
        self.slipped_s = 0.0

    def record_lateness(self, lateness: float) -> None:
        """A substep boundary processed ``lateness`` wall seconds after its deadline."""
        self.pacing_error.add(lateness)
        if lateness > self.period:
            self.overruns += 1

    def record_slip(self, seconds: float) -> None:
        """The clock slipped by ``seconds`` (wall seconds not simulated)."""
        self.slips += 1
        self.slipped_s += seconds

    def timing(self) -> dict[str, Any]:
        """Pacing figures of this world (wall seconds)."""
        return {
            "pacing_error_s": self.pacing_error.summary(),
            "apply_delay_s": self.apply_delay.summary(),
            "overruns": self.overruns,
            "substeps": self.substeps,
            "period_s": self.period,
            "link_delay_s": self.link_delay.summary(),
            "clock_slips": self.slips,
            "slipped_s": self.slipped_s,
        }

    def clear_timing(self) -> None:
        """Start every figure afresh (the ``timing`` command's ``clear``)."""
        self.pacing_error.clear()
        self.apply_delay.clear()
        self.link_delay.clear()
        self.overruns = 0
        self.substeps = 0
        self.slips = 0
        self.slipped_s = 0.0


__all__ = ["CATCH_UP_LIMIT_S", "PacingFigures"]
