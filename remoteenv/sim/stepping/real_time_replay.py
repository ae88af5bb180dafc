"""A real-time world replaying a recorded episode without a clock (the exact twin).

Runs in the sim process. A ``reset`` whose options carry a replay schedule
(:mod:`remoteenv.wire.run_options.real_time_modes`) puts a
:class:`~remoteenv.sim.stepping.real_time_world.RealTimeStepper` into replay
for that episode: its clock is not consulted, no substep runs on a deadline,
and each ``step`` runs the world's substep boundaries back to back, with the
step's action taken as arrived just before the substep the schedule names,
until the reply real time would have sent. The boundaries are processed by
the same code as on the wall clock (score the tick with the held action,
apply the newly arrived one, step), so physics, rewards and flags are
those of the recorded run, bit for bit. The work one step may cause is
bounded: at most :data:`~remoteenv.wire.run_options.real_time_modes.MAX_REPLAY_STEP_TICKS`
ticks, and a scene's cameras render only the ticks whose observation a reply
carries (the real run's replies), not every tick run on the way.
"""

from __future__ import annotations

from typing import Any

from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.run_options.real_time_modes import MAX_REPLAY_STEP_TICKS, split_replay_schedule
from remoteenv.wire.wire_errors import PROTOCOL


def replay_from_options(
    options: dict[str, Any] | None, mode: str, frame_skip: int, has_link: bool
) -> tuple[dict[str, Any] | None, ReplayCursor | None]:
    """A reset's options for the scene, and the replay their schedule asks for
    (None: none), for a world of ``mode`` that emulates a link or not. Raises a
    protocol :class:`RequestError` for a malformed schedule, one of another
    regime, or link delays for a world without an emulated link."""
    try:
        options, schedule = split_replay_schedule(options, mode)
    except ValueError as exc:
        raise RequestError(PROTOCOL, str(exc)) from None
    if schedule is None:
        return options, None
    if schedule.link_delays is not None and not has_link:
        raise RequestError(
            PROTOCOL,
            "this replay carries the emulated link delays of its recording, but this sim emulates no link: "
            "launch the twin with the recording's link_delay",
        )
    return options, ReplayCursor(schedule.action_substeps, frame_skip, schedule.link_delays)


class ReplayCursor:
    """The schedule of one replayed episode: which substep each step's action takes effect at.

    Args:
        action_substeps: per step, the substep (counted from the reset) at
            which its action took effect in the recorded run (checked by
            :func:`remoteenv.wire.run_options.real_time_modes.split_replay`).
        frame_skip: substeps per control tick.
        link_delays: per step, the emulated link delay the recorded run
            reported (wall seconds; None: none recorded, 0.0 is replayed).
    """

    def __init__(self, action_substeps: list[int], frame_skip: int, link_delays: list[float] | None = None) -> None:
        self.action_substeps = action_substeps
        self.frame_skip = frame_skip
        self.link_delays = link_delays
        #: Steps replayed since the reset.
        self.steps = 0
        #: The recorded link delay of the step :meth:`next_substep` last returned.
        self.link_delay = 0.0

    def next_substep(self, current: int) -> int:
        """The substep at which the next step's action takes effect; ``current``
        is the world's next substep. Raises a protocol :class:`RequestError`
        beyond the recording or for a step that would span more than
        ``MAX_REPLAY_STEP_TICKS`` ticks (a bound on the work one request may ask for)."""
        j = self.steps
        if j >= len(self.action_substeps):
            raise RequestError(
                PROTOCOL,
                f"the replayed episode was recorded with {len(self.action_substeps)} steps; step {j + 1} is "
                "beyond the recording (the twin's policy acted differently, or the episode was cut short): reset",
            )
        target = self.action_substeps[j]
        span = target - current
        if span > MAX_REPLAY_STEP_TICKS * self.frame_skip:
            raise RequestError(
                PROTOCOL,
                f"replay step {j} would run {span} substeps (about {span // self.frame_skip} ticks of "
                f"{self.frame_skip}), more than the {MAX_REPLAY_STEP_TICKS} "
                "ticks one replayed step may run: this episode cannot be replayed",
            )
        self.link_delay = 0.0 if self.link_delays is None else self.link_delays[j]
        self.steps += 1
        return target


__all__ = ["ReplayCursor", "replay_from_options"]
