"""Real time on an emulated link, and pause/resume, on a fake clock.

The clock is a number the test sets; nothing here waits or reads the wall
clock, so every figure is exact.
"""

from __future__ import annotations

from typing import Any

import pytest

from remoteenv.delays import Constant, Uniform
from remoteenv.sim.stepping.real_time import RealTimeStepper, RealTimeStepping
from remoteenv.wire.delays.delay_line import LINK_STREAM, delay_rng
from remoteenv.wire.run_options.options import RunOptions
from tests.unit.test_real_time_stepper import T0, TIMESTEP, FakeClock, TickWorld, run_until, start


def make_linked(link: Any, seed: int | None = None) -> tuple[RealTimeStepper, TickWorld, FakeClock]:
    clock = FakeClock(T0 - 1.0)
    world = TickWorld()
    stepper = RealTimeStepper(world, RunOptions(real_time=True, link_delay=link), clock=clock, seed=seed)  # type: ignore[arg-type]
    return stepper, world, clock


def test_a_link_delay_holds_the_action_back_by_its_draw():
    stepper, world, clock = make_linked(0.02)  # a number means Constant(0.02 s)
    start(stepper, clock)
    run_until(stepper, clock, T0 + 0.005)
    assert stepper.submit(1, "a", None, None) is None
    # Without the link it would apply at boundary 1 (0.01); held back until 0.025, it applies at 0.03.
    assert run_until(stepper, clock, T0 + 0.025) == []
    assert all(a != "a" for _, a in world.applied)
    ((_, _, reply),) = run_until(stepper, clock, T0 + 0.04)
    assert (3, "a") in world.applied
    info = reply["info"]
    assert info["link_delay_s"] == 0.02
    assert info["apply_delay_s"] == pytest.approx(0.025)  # the link's 0.02 plus the wait for boundary 3
    assert info["action_sim_time"] == pytest.approx(0.03)
    assert stepper.timing()["link_delay_s"]["max"] == 0.02


def test_link_delays_are_drawn_from_the_seeded_link_stream():
    spec = Uniform(0.001, 0.05, unit="s")
    stepper, world, clock = make_linked(spec)
    stepper.reset(seed=9, options=None)
    clock.t = T0
    stepper.start(T0)
    drawn = []
    for seq in range(5):
        stepper.submit(seq, seq, None, None)
        drawn.append(stepper._pending.link_delay)  # type: ignore[union-attr]
        run_until(stepper, clock, clock.t + 0.2)
    rng = delay_rng(9, LINK_STREAM)
    assert drawn == [spec.sample(rng, i) for i in range(5)]
    assert stepper.describe()["link_delay_spec"] == spec.to_wire()


def test_the_launch_seed_seeds_the_link_until_a_reset_brings_one():
    a = make_linked(Uniform(0.0, 0.05, unit="s"), seed=3)[0]
    b = make_linked(Uniform(0.0, 0.05, unit="s"), seed=3)[0]
    for stepper in (a, b):
        stepper.reset(seed=None, options=None)
    assert a.link is not None and b.link is not None and a.link.draw() == b.link.draw()


def test_without_a_link_nothing_is_drawn_and_info_has_no_link_key():
    stepper, world, clock = make_linked(None)
    assert stepper.link is None and "link_delay_spec" not in stepper.describe()
    start(stepper, clock)
    stepper.submit(1, "a", None, None)
    ((_, _, reply),) = run_until(stepper, clock, T0 + 0.04)
    assert "link_delay_s" not in reply["info"]  # the key comes with an emulated link only


def test_pause_stops_physics_keeps_the_held_action_and_shifts_deadlines():
    stepper, world, clock = make_linked(None)
    start(stepper, clock)
    stepper.submit(1, "a", None, None)
    run_until(stepper, clock, T0 + 0.04)
    substeps, sim_time = world.substeps, world.data.time
    stepper.pause(T0 + 0.043)
    assert stepper.paused and stepper.next_deadline() is None
    assert run_until(stepper, clock, T0 + 10.0) == [] and world.substeps == substeps
    assert world.data.time == sim_time and world.applied[-1] == (4, "a")  # "a" still held
    clock.t = T0 + 10.043
    assert stepper.resume(T0 + 10.043) == pytest.approx(10.0)
    # The next boundary (5, due at T0 + 0.05 before the pause) is now due 10 s later.
    assert stepper.next_deadline() == pytest.approx(T0 + 10.05)
    stepper.submit(2, "b", None, None)
    ((_, _, reply),) = run_until(stepper, clock, T0 + 10.08)
    assert world.applied[-2:] == [(5, "b"), (8, "b")]
    # The pause is in no figure: no overrun, no pacing error beyond zero, apply delay 7 ms.
    assert stepper.overruns == 0 and stepper.pacing_error.summary()["max"] == pytest.approx(0.0, abs=1e-9)
    assert reply["info"]["apply_delay_s"] == pytest.approx(0.007)
    assert reply["info"]["latency_s"] == pytest.approx(0.05 - 0.04)


def test_a_request_waiting_during_a_pause_counts_only_unpaused_time():
    stepper, world, clock = make_linked(None)
    start(stepper, clock)
    run_until(stepper, clock, T0 + 0.001)
    clock.t = T0 + 0.002
    stepper.submit(1, "a", None, None)  # arrives 8 ms before boundary 1
    stepper.pause(T0 + 0.004)
    stepper.resume(T0 + 5.004)
    ((_, _, reply),) = run_until(stepper, clock, T0 + 5.04)
    assert reply["info"]["apply_delay_s"] == pytest.approx(0.008)


def test_pausing_twice_and_resuming_unpaused_change_nothing():
    stepper, world, clock = make_linked(None)
    start(stepper, clock)
    assert stepper.resume(T0) == 0.0
    stepper.pause(T0 + 1)
    stepper.pause(T0 + 2)
    assert stepper.resume(T0 + 3) == pytest.approx(2.0)
    assert stepper.next_deadline() == pytest.approx(T0 + 2.0)


def test_a_world_reset_while_paused_starts_paused():
    stepper, world, clock = make_linked(None)
    stepper.pause(T0 - 1.0)
    start(stepper, clock)
    assert stepper.next_deadline() is None
    stepper.resume(T0 + 4.0)
    assert stepper.next_deadline() == pytest.approx(T0 + 4.0)


def test_the_pause_and_resume_commands_cover_every_world():
    clock = FakeClock(T0)
    stepping = RealTimeStepping([TickWorld(), TickWorld()], clock=clock)  # type: ignore[list-item]
    for world in stepping.worlds:
        world.reset(seed=None, options=None)
    stepping.start_clocks(T0)
    list(stepping.run_due(T0 + 0.021))  # one boundary per world per call: boundary 0
    reply = stepping.pause({}, None, None)
    assert reply == {"sim_time": [pytest.approx(0.01)] * 2}
    assert stepping.next_deadline() is None
    clock.t = T0 + 3.0
    reply = stepping.resume({}, None, None)
    assert reply["paused_s"] == pytest.approx(3.0) and stepping.next_deadline() == pytest.approx(T0 + 3.0 + TIMESTEP)


def test_link_delay_specs_must_be_in_seconds():
    with pytest.raises(ValueError, match="seconds|s"):
        RealTimeStepper(TickWorld(), RunOptions(real_time=True, link_delay=Constant(2)))  # type: ignore[arg-type]
