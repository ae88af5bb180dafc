"""Real time during a catch-up, on a fake clock: no action acts in the past.

When the sim falls behind (a stall: a slow render, descheduling) it runs the
overdue substep boundaries back to back. Each boundary runs with the action
that had arrived by its *deadline* (``t0 + n * period``); an action read
while the sim catches up takes effect at the first boundary whose deadline
is at or after the moment it was read. The clock is a number the tests set
(see tests/unit/test_real_time_stepper.py, whose stand-in world is used).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from remoteenv.sim.stepping.real_time import RealTimeStepper
from remoteenv.sim.stepping.real_time_pacing import CATCH_UP_LIMIT_S
from remoteenv.wire.run_options.options import RunOptions
from tests.unit.test_real_time_stepper import DT, FRAME_SKIP, T0, TIMESTEP, FakeClock, TickWorld, run_until


def make(mode: str, world: Any = None, link_delay: float | None = None) -> tuple[RealTimeStepper, Any, FakeClock]:
    clock = FakeClock(T0 - 1.0)
    world = world or TickWorld()
    run = RunOptions(real_time=True, real_time_mode=mode, link_delay=link_delay)
    stepper = RealTimeStepper(world, run, clock=clock, seed=0)
    stepper.reset(seed=None, options=None)
    clock.t = T0
    stepper.start(T0)
    return stepper, world, clock


def catch_up(stepper: RealTimeStepper, clock: FakeClock, now: float) -> list[Any]:
    """The sim wakes at ``now`` after a stall and processes every overdue boundary at once (late)."""
    clock.t = now
    out = []
    while (deadline := stepper.next_deadline()) is not None and deadline <= now:
        out += stepper.advance(now)
    return out


def at(n: float) -> float:
    """Clock time of substep boundary ``n`` (fractions: between boundaries)."""
    return T0 + n * TIMESTEP


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_an_action_read_during_a_catch_up_waits_for_a_boundary_whose_deadline_follows_its_reading(mode):
    stepper, world, clock = make(mode)
    run_until(stepper, clock, at(2))  # boundaries 0..2 on time
    # The sim stalls after boundary 2; it wakes at 20.3 substeps and reads the
    # action the agent sent meanwhile (it cannot know when it came).
    clock.t = at(20.3)
    assert stepper.submit(1, "a", None, None) is None
    out = catch_up(stepper, clock, at(20.3))  # boundaries 3..20 are overdue
    assert out == [] and all(action != "a" for _, action in world.applied)
    first = 21 if mode == "elastic" else 24  # the first (tick) boundary due at or after 20.3
    while not out:
        out = run_until(stepper, clock, stepper.next_deadline())
    info = out[0][2]["info"]
    assert info["action_substep"] == first and (first, "a") in world.applied
    assert info["latency_s"] >= 20.3 * TIMESTEP  # never below the time from the last observation to its reading
    assert info["late"] and info["ticks_elapsed"] == (first + FRAME_SKIP - 1) // FRAME_SKIP
    if mode == "fixed_step":
        assert info["latency_ticks"] == info["ticks_elapsed"] == 6 and info["substep"] == first
    assert out[0][2]["reward"] == sum(range(1, info["ticks_elapsed"] + 1))  # every tick of the step, scored


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_overdue_boundaries_run_with_the_action_in_force_at_their_deadline(mode):
    stepper, world, clock = make(mode)
    run_until(stepper, clock, at(2.5))
    assert stepper.submit(1, "early", None, None) is None  # read at 2.5, before the stall
    # The sim stalls before boundary 3 and wakes at 13.5: "early" was there by
    # boundary 3's deadline (4 in fixed step), so it acts there, though processed late.
    out = catch_up(stepper, clock, at(13.5))
    where = 3 if mode == "elastic" else 4
    assert (where, "early") in world.applied
    (reply,) = [o[2] for o in out]
    assert reply["info"]["action_substep"] == where
    # The next action, read at 13.7 while boundaries up to 13 were processed: it acts at 14 (16 in fixed step).
    clock.t = at(13.7)
    stepper.submit(2, "next", None, None)
    out = []
    while not out:
        out = run_until(stepper, clock, stepper.next_deadline())
    assert out[0][2]["info"]["action_substep"] == (14 if mode == "elastic" else 16)


def test_the_emulated_link_delay_counts_from_the_reading_against_deadlines():
    stepper, world, clock = make("elastic", link_delay=3.2 * TIMESTEP)
    run_until(stepper, clock, at(2))
    clock.t = at(9.5)
    stepper.submit(1, "a", None, None)  # read at 9.5, held back 3.2 substeps: usable from 12.7
    out = catch_up(stepper, clock, at(14.0))  # boundaries 3..14, all processed at 14
    assert [n for n, action in world.applied if action == "a"] == [13]
    while not out:
        out = run_until(stepper, clock, stepper.next_deadline())
    assert out[0][2]["info"]["action_substep"] == 13


def test_an_action_sent_during_a_pause_acts_at_the_first_boundary_after_the_resume():
    stepper, world, clock = make("elastic")
    run_until(stepper, clock, at(2))
    stepper.pause(at(2.2))
    clock.t = at(7.0)  # long after boundary 3's unpaused deadline
    stepper.submit(1, "a", None, None)
    stepper.resume(at(9.0))  # paused 6.8 substeps: boundary 3 is due at 9.8
    out = []
    while not out:
        out = run_until(stepper, clock, stepper.next_deadline())
    assert out[0][2]["info"]["action_substep"] == 3


class LoopOnAFakeClock:
    """The server loop around one world, on a fake clock, with stalls.

    Each pass: while the sim is stalled, time jumps to the stall's end; a due
    boundary is processed (``cost`` of a substep period each); then the
    channel is read. The agent answers each reply after thinking; its
    request is read at the first pass at or after it was sent.
    """

    def __init__(self, mode: str, rng: np.random.Generator) -> None:
        self.stepper, self.world, self.clock = make(mode)
        self.rng = rng
        self.stalls: list[tuple[float, float]] = []

    def stall_between(self, start: float, length: float) -> None:
        self.stalls.append((start, start + length))

    def _awake(self, t: float) -> float:
        for start, end in self.stalls:
            if start <= t < end:
                return end
        return t

    def step(self, sent: float, action: Any, seq: int, cost: float) -> tuple[dict[str, Any], float]:
        """Send ``action`` at ``sent``; the reply and the clock time it was sent."""
        stepper, clock = self.stepper, self.clock
        read = False
        while True:
            now = self._awake(clock.t)
            deadline = stepper.next_deadline()
            assert deadline is not None
            if not read and sent <= now:
                clock.t = now
                assert stepper.submit(seq, action, None, None) is None
                read = True
            if deadline <= now:
                clock.t = now
                out = stepper.advance(now)
                clock.t = now + cost * stepper.period
                if out:
                    return out[0][2], now
                continue
            # Nothing due: sleep to the next deadline or the request's sending.
            clock.t = min(deadline, sent) if not read else deadline
            if clock.t < now:
                clock.t = now


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_fuzz_no_action_acts_at_a_substep_whose_deadline_preceded_its_sending(mode):
    rng = np.random.default_rng(5)
    loop = LoopOnAFakeClock(mode, rng)
    period = loop.stepper.period
    received, last_substep = T0, 0
    for seq in range(400):
        think = rng.uniform(0.0, 2.0) * DT
        sent = received + think
        if rng.random() < 0.5:  # a stall starting around the sending, of 0..5 ticks
            loop.stall_between(sent + rng.uniform(-1.0, 0.5) * DT, rng.uniform(0.0, 5.0) * DT)
        reply, received = loop.step(sent, seq, seq, cost=rng.uniform(0.0, 0.3))
        info = reply["info"]
        applied = info["action_substep"]
        assert applied is not None
        assert T0 + applied * period >= sent - 1e-12, (seq, info)
        assert info["latency_s"] >= think - 1e-9, (seq, info)  # factor 1: sim seconds = wall seconds
        assert info["ticks_elapsed"] * FRAME_SKIP == info["substep"] - last_substep
        assert info["late"] == (info["ticks_elapsed"] > 1)
        if mode == "fixed_step":
            assert info["latency_ticks"] == info["ticks_elapsed"] and applied == info["substep"]
        last_substep = info["substep"]


def test_a_sim_too_far_behind_slips_its_clock_and_still_applies_the_action():
    stepper, world, clock = make("elastic")
    run_until(stepper, clock, at(2))
    late = CATCH_UP_LIMIT_S + 0.5
    clock.t = at(2.5) + late
    stepper.submit(1, "a", None, None)
    out = catch_up(stepper, clock, clock.t)  # boundary 3 is processed more than the limit late
    timing = stepper.timing()
    assert timing["clock_slips"] == 1 and timing["slipped_s"] == pytest.approx(late - 0.5 * TIMESTEP)
    assert (3, "a") in world.applied  # boundary 3 is now due at the moment it was processed
    assert stepper.next_deadline() == pytest.approx(clock.t + TIMESTEP)  # the later deadlines moved with it
    while not out:
        out = run_until(stepper, clock, stepper.next_deadline())
    assert out[0][2]["info"]["action_substep"] == 3
    stepper.clear_timing()
    assert stepper.timing()["clock_slips"] == 0 and stepper.timing()["slipped_s"] == 0.0
