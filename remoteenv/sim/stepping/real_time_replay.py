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
those of the recorded run, bit for bit.
"""

from __future__ import annotations

from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.delays.delay_specs import MAX_DELAY_TICKS
from remoteenv.wire.wire_errors import PROTOCOL


class ReplayCursor:
    """The schedule of one replayed episode: which substep each step's action takes effect at.

    Args:
        action_substeps: per step, the substep (counted from the reset) at
            which its action took effect in the recorded run (checked by
            :func:`remoteenv.wire.run_options.real_time_modes.split_replay`).
        frame_skip: substeps per control tick.
    """

    def __init__(self, action_substeps: list[int], frame_skip: int) -> None:
        self.action_substeps = action_substeps
        self.frame_skip = frame_skip
        #: Steps replayed since the reset.
        self.steps = 0

    def next_substep(self, current: int) -> int:
        """The substep at which the next step's action takes effect; ``current``
        is the world's next substep. Raises a protocol :class:`RequestError`
        beyond the recording or for a step that would span more than
        ``MAX_DELAY_TICKS`` ticks (a bound on the work one request may ask for)."""
        j = self.steps
        if j >= len(self.action_substeps):
            raise RequestError(
                PROTOCOL,
                f"the replayed episode was recorded with {len(self.action_substeps)} steps; step {j + 1} is "
                "beyond the recording (the twin's policy acted differently, or the episode was cut short): reset",
            )
        target = self.action_substeps[j]
        if target - current > MAX_DELAY_TICKS * self.frame_skip:
            raise RequestError(
                PROTOCOL,
                f"replay step {j} would run {target - current} substeps, more than {MAX_DELAY_TICKS} ticks",
            )
        self.steps += 1
        return target


__all__ = ["ReplayCursor"]
