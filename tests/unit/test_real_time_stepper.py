"""Real-time stepping on a fake clock: deadlines, when actions take effect, when
replies go, summed rewards, the freeze at termination, overruns.

The clock is a number the test sets; no test waits or reads the wall clock.
Most tests drive a stand-in world whose every substep and tick is recorded;
the last one replays a real MuJoCo scene substep by substep.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.stepping.real_time import RealTimeStepper, RealTimeStepping
from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.run_options.options import RunOptions

TIMESTEP = 0.01  # simulated seconds per substep
FRAME_SKIP = 4  # substeps per control tick
DT = TIMESTEP * FRAME_SKIP
T0 = 100.0  # clock time at which the episode's clock starts


class FakeClock:
    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


class TickWorld:
    """Stands in for a BaseEnv: substep ``n`` ends at sim time ``n * TIMESTEP``;
    tick ``k`` (from 1) scores reward ``k`` and terminates when ``k == end_tick``."""

    def __init__(self, end_tick: int | None = None, fail_at_substep: int | None = None) -> None:
        self.model = SimpleNamespace(opt=SimpleNamespace(timestep=TIMESTEP))
        self.data = SimpleNamespace(time=0.0)
        self.frame_skip = FRAME_SKIP
        self.end_tick = end_tick
        self.fail_at_substep = fail_at_substep
        self.reset(seed=None, options=None)

    @property
    def dt(self) -> float:
        return TIMESTEP * self.frame_skip

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        self.data.time = 0.0
        self.substeps = 0
        self.ticks = 0
        #: (substep index, action) of every prepare_step call.
        self.applied: list[tuple[int, Any]] = []
        #: The ticks whose observation was rendered (finish_tick's observe, or observe).
        self.observed: list[int] = []
        return np.zeros(1), {"reset": True}

    def default_action(self) -> Any:
        return None

    def prepare_step(self, action: Any) -> None:
        self.applied.append((self.substeps, action))

    def substep(self) -> None:
        if self.substeps == self.fail_at_substep:
            raise RuntimeError("the scene broke")
        self.substeps += 1
        self.data.time = self.substeps * TIMESTEP

    def post_step(self, action: Any) -> tuple[Any, float, bool, dict[str, Any]]:
        self.ticks += 1
        return np.array([float(self.ticks)]), float(self.ticks), self.ticks == self.end_tick, {"tick": self.ticks}

    # BaseEnv's post_step with the observation check; the stepper calls this one.
    # ``observe`` (rendering, in a scene with cameras) is counted in ``observed``.
    def finish_tick(self, action: Any, *, observe: bool = True) -> tuple[Any, float, bool, dict[str, Any]]:
        result = self.post_step(action)
        if observe:
            self.observed.append(self.ticks)
        return result

    def observe(self, state: Any) -> Any:
        self.observed.append(self.ticks)
        return state


def make(world: TickWorld | None = None, factor: float = 1.0) -> tuple[RealTimeStepper, TickWorld, FakeClock]:
    clock = FakeClock(T0 - 1.0)
    world = world or TickWorld()
    stepper = RealTimeStepper(world, RunOptions(real_time=True, real_time_factor=factor), clock=clock)  # type: ignore[arg-type]
    return stepper, world, clock


def start(stepper: RealTimeStepper, clock: FakeClock) -> None:
    stepper.reset(seed=None, options=None)
    clock.t = T0
    stepper.start(T0)


def run_until(stepper: RealTimeStepper, clock: FakeClock, t: float) -> list[Any]:
    """Process every substep boundary due by clock time ``t``, each exactly on its deadline."""
    out = []
    while (deadline := stepper.next_deadline()) is not None and deadline <= t + 1e-12:
        clock.t = deadline
        out += stepper.advance(deadline)
    clock.t = t
    return out


def test_nothing_runs_before_the_reset_or_before_the_clock_starts():
    stepper, world, clock = make()
    assert not stepper.has_reset and stepper.next_deadline() is None and not stepper.awaiting_clock
    stepper.reset(seed=None, options=None)
    assert stepper.has_reset and stepper.awaiting_clock and stepper.next_deadline() is None
    stepper.start(T0)
    assert stepper.running and not stepper.awaiting_clock
    stepper.start(T0 + 5)  # a started clock is not restarted
    assert stepper.next_deadline() == T0


@pytest.mark.parametrize("factor", [1.0, 2.0, 0.5])
def test_deadlines_are_absolute_and_follow_the_factor(factor):
    stepper, world, clock = make(factor=factor)
    start(stepper, clock)
    period = TIMESTEP / factor
    assert stepper.period == pytest.approx(period)
    for n in range(10):
        assert stepper.next_deadline() == pytest.approx(T0 + n * period)
        # Processing a boundary late does not move the later deadlines.
        stepper.advance(T0 + n * period + 0.3 * period)
    assert world.substeps == 10 and stepper.substeps == 10


def test_an_action_takes_effect_at_the_next_substep_and_is_answered_at_the_end_of_that_tick():
    stepper, world, clock = make()
    start(stepper, clock)
    assert run_until(stepper, clock, T0 + 0.025) == []  # boundaries 0, 1, 2 on the default action
    channel: Any = object()
    assert stepper.submit(7, "a", channel, "peer") is None  # answered later
    out = run_until(stepper, clock, T0 + 0.03)  # boundary 3: the action takes effect
    assert out == [] and world.applied == [(0, None), (3, "a")]
    out = run_until(stepper, clock, T0 + 0.04)  # boundary 4 ends tick 1, the first with "a" in force
    assert len(out) == 1
    to, reply_to, reply = out[0]
    assert to is channel and reply_to == "peer"
    assert reply["seq"] == 7 and reply["ok"] and reply["terminated"] is False and reply["truncated"] is False
    assert reply["reward"] == 1.0 and reply["obs"][0] == 1.0
    info = reply["info"]
    assert info["tick"] == 1  # the scene's info of the last tick
    assert info["sim_time"] == pytest.approx(0.04) and info["action_sim_time"] == pytest.approx(0.03)
    assert info["ticks_elapsed"] == 1 and info["late"] is False
    assert info["latency_s"] == pytest.approx(0.03) and info["latency_ticks"] == pytest.approx(0.03 / DT)
    assert info["apply_delay_s"] == pytest.approx(0.005)  # clock seconds from submit to boundary 3
    assert stepper.apply_delay.count == 1
    # The action is held: applied again at the start of the next tick.
    assert world.applied[-1] == (4, "a")


def test_an_action_arriving_in_a_ticks_last_substep_is_answered_a_tick_later():
    stepper, world, clock = make()
    start(stepper, clock)
    run_until(stepper, clock, T0 + 0.035)  # boundaries 0..3 ran; boundary 4 ends tick 1
    stepper.submit(1, "a", None, None)
    assert run_until(stepper, clock, T0 + 0.04) == []  # tick 1 ran without "a": no reply yet
    assert world.applied[-1] == (4, "a")  # "a" takes effect as tick 2 starts
    assert run_until(stepper, clock, T0 + 0.075) == []
    ((_, _, reply),) = run_until(stepper, clock, T0 + 0.08)  # end of tick 2
    assert reply["reward"] == 1.0 + 2.0 and reply["info"]["ticks_elapsed"] == 2
    assert reply["info"]["action_sim_time"] == pytest.approx(0.04) and reply["info"]["late"] is True


def test_reward_is_summed_over_every_tick_since_the_last_reply():
    stepper, world, clock = make()
    start(stepper, clock)
    run_until(stepper, clock, T0 + 0.105)  # ticks 1 and 2 end at boundaries 4 and 8
    assert stepper.submit(1, "a", None, None) is None
    out = run_until(stepper, clock, T0 + 0.12)  # applied at boundary 11; tick 3 ends at 12
    ((_, _, reply),) = out
    assert reply["reward"] == 1.0 + 2.0 + 3.0
    info = reply["info"]
    assert info["ticks_elapsed"] == 3 and info["late"] is True
    assert info["action_sim_time"] == pytest.approx(0.11)
    assert info["latency_s"] == pytest.approx(0.11) and info["latency_ticks"] == pytest.approx(0.11 / DT)
    # The next reply counts from here: one tick, its reward only.
    assert stepper.submit(2, "b", None, None) is None
    ((_, _, reply),) = run_until(stepper, clock, T0 + 0.16)
    assert reply["reward"] == 4.0 and reply["info"]["ticks_elapsed"] == 1
    assert reply["info"]["latency_s"] == pytest.approx(0.13 - 0.12)


def test_a_newer_step_supersedes_one_not_yet_applied():
    stepper, world, clock = make()
    start(stepper, clock)
    run_until(stepper, clock, T0 + 0.005)
    stepper.submit(1, "old", None, "first")
    stepper.submit(2, "new", None, "second")
    out = run_until(stepper, clock, T0 + 0.04)
    assert [(reply_to, reply["seq"]) for _, reply_to, reply in out] == [("second", 2)]
    assert (1, "new") in world.applied and all(a != "old" for _, a in world.applied)


def test_termination_freezes_the_world_until_the_next_reset():
    stepper, world, clock = make(TickWorld(end_tick=2))
    start(stepper, clock)
    run_until(stepper, clock, T0 + 0.075)
    # Sent just before the boundary that ends the episode: it never takes effect.
    assert stepper.submit(1, "late", None, None) is None
    ((_, _, reply),) = run_until(stepper, clock, T0 + 1.0)
    assert reply["terminated"] is True and reply["reward"] == 1.0 + 2.0
    info = reply["info"]
    assert info["action_sim_time"] is None and info["latency_s"] is None and info["latency_ticks"] is None
    assert info["late"] is True and info["ticks_elapsed"] == 2 and info["sim_time"] == pytest.approx(0.08)
    assert stepper.next_deadline() is None and world.substeps == 8  # frozen at the termination
    assert all(a != "late" for _, a in world.applied)
    # While frozen a step is answered at once, with nothing new.
    again = stepper.submit(2, "x", None, None)
    assert again is not None and again["seq"] == 2 and again["terminated"] is True
    assert again["reward"] == 0.0 and again["info"]["ticks_elapsed"] == 0
    assert again["info"]["sim_time"] == pytest.approx(0.08)
    # A reset restarts the clock from its own moment.
    stepper.reset(seed=None, options=None)
    assert stepper.awaiting_clock
    stepper.start(T0 + 5.0)
    assert stepper.next_deadline() == T0 + 5.0


def test_substeps_more_than_one_period_late_are_counted_as_overruns():
    stepper, world, clock = make()
    start(stepper, clock)
    stepper.advance(T0 + 0.5 * TIMESTEP)  # late, but less than a period
    stepper.advance(T0 + TIMESTEP + 1.5 * TIMESTEP)  # more than a period late
    stepper.advance(T0 + 2 * TIMESTEP - 0.001)  # early
    assert stepper.overruns == 1
    assert stepper.pacing_error.count == 3
    assert stepper.pacing_error.max == pytest.approx(1.5 * TIMESTEP)
    stepper.submit(1, "a", None, None)
    ((_, _, reply),) = run_until(stepper, clock, T0 + 0.04)
    assert reply["info"]["pacing_overruns"] == 1
    timing = stepper.timing()
    assert timing["overruns"] == 1 and timing["substeps"] == 5 and timing["period_s"] == pytest.approx(TIMESTEP)
    assert timing["pacing_error_s"]["count"] == 5 and timing["apply_delay_s"]["count"] == 1
    stepper.clear_timing()
    assert stepper.timing()["overruns"] == 0 and stepper.timing()["pacing_error_s"]["count"] == 0


@pytest.mark.parametrize("factor", [0.0, -1.0, float("nan"), float("inf")])
def test_impossible_factors_are_refused(factor):
    with pytest.raises(ValueError, match="real_time_factor"):
        RealTimeStepper(TickWorld(), RunOptions(real_time=True, real_time_factor=factor))  # type: ignore[arg-type]


# ---------------------------------------------------------------- several worlds


def make_stepping(*worlds: TickWorld) -> tuple[RealTimeStepping, FakeClock]:
    clock = FakeClock(T0)
    return RealTimeStepping(worlds, clock=clock), clock  # type: ignore[arg-type]


def test_each_world_runs_its_own_schedule_on_the_one_clock():
    a, b = TickWorld(), TickWorld()
    stepping, clock = make_stepping(a, b)
    assert stepping.next_deadline() is None and not stepping.clock_waiting
    stepping.worlds[0].reset(seed=None, options=None)
    assert stepping.clock_waiting
    stepping.start_clocks(T0)
    assert not stepping.clock_waiting and stepping.next_deadline() == T0
    stepping.worlds[1].reset(seed=None, options=None)
    stepping.start_clocks(T0 + 0.015)  # starts world 1 only
    assert stepping.worlds[0].next_deadline() == T0
    assert stepping.worlds[1].next_deadline() == T0 + 0.015
    clock.t = T0 + 0.011
    assert list(stepping.run_due(clock.t)) == []
    assert (a.substeps, b.substeps) == (1, 0)  # one boundary per world per call; world 1 not due
    assert stepping.next_deadline() == pytest.approx(T0 + 0.01)
    list(stepping.run_due(clock.t))
    assert (a.substeps, b.substeps) == (2, 0)
    clock.t = T0 + 0.016
    list(stepping.run_due(clock.t))
    assert (a.substeps, b.substeps) == (2, 1)  # world 0's next boundary is at T0 + 0.02


def test_a_scene_failure_stops_only_its_world_and_answers_with_a_scene_error():
    broken, fine = TickWorld(fail_at_substep=2), TickWorld()
    stepping, clock = make_stepping(broken, fine)
    for w in stepping.worlds:
        w.reset(seed=None, options=None)
    stepping.start_clocks(T0)
    stepping.worlds[0].submit(5, "a", None, "peer")
    replies = []
    for n in range(3):
        clock.t = T0 + n * TIMESTEP
        replies += list(stepping.run_due(clock.t))
    ((_, reply_to, reply),) = replies
    assert reply_to == "peer" and reply["seq"] == 5 and not reply["ok"]
    assert reply["error"]["kind"] == "scene" and "the scene broke" in reply["error"]["message"]
    assert "Traceback" in reply["error"]["message"]
    assert stepping.worlds[0].next_deadline() is None and fine.substeps == 3
    with pytest.raises(RequestError) as err:
        stepping.worlds[0].submit(6, "a", None, None)
    assert err.value.kind == "scene"
    stepping.worlds[0].reset(seed=None, options=None)  # a reset recovers
    assert stepping.worlds[0].submit(7, "a", None, None) is None


def test_timing_command_reports_every_world_and_clears_on_request():
    stepping, clock = make_stepping(TickWorld(), TickWorld())
    stepping.worlds[0].reset(seed=None, options=None)
    stepping.start_clocks(T0)
    list(stepping.run_due(T0))
    reply = stepping.timing({"seq": 1, "cmd": "timing", "clear": True}, None, None)
    assert [w["substeps"] for w in reply["worlds"]] == [1, 0]
    assert stepping.timing({"seq": 2, "cmd": "timing"}, None, None)["worlds"][0]["substeps"] == 0


# ---------------------------------------------------------------- a real scene


def test_a_real_scene_matches_a_substep_replay_with_the_action_switched_where_reported():
    env = CartPoleEnv(continuous=True)
    clock = FakeClock(T0)
    stepping = RealTimeStepping([env], clock=clock)
    world = stepping.worlds[0]
    world.reset(seed=3, options=None)
    stepping.start_clocks(T0)
    period = world.period
    actions = [np.array([0.4], np.float32), np.array([-0.7], np.float32), np.array([0.1], np.float32)]

    def next_deadline() -> float:
        deadline = world.next_deadline()
        assert deadline is not None
        return deadline

    # Let the held action run for a while (7k substeps), submit the next one
    # between two substep boundaries, then run until its reply comes.
    replies = []
    for k, action in enumerate(actions):
        for _ in range(7 * k):
            clock.t = next_deadline()
            assert list(stepping.run_due(clock.t)) == []
        clock.t = next_deadline() - 0.3 * period
        world.submit(k, action, None, None)
        got: list[Any] = []
        while not got:
            clock.t = next_deadline()
            got = list(stepping.run_due(clock.t))
        replies.append(got[0][2])

    replay = CartPoleEnv(continuous=True)
    replay.reset(seed=3)
    switches = {round(r["info"]["action_sim_time"] / env.model.opt.timestep): a for r, a in zip(replies, actions)}
    held: Any = replay.default_action()
    fs = replay.frame_skip
    obs_at_tick = {}
    rewards = []
    last_tick = round(replies[-1]["info"]["sim_time"] / replay.dt)
    for n in range(last_tick * fs + 1):
        if n and n % fs == 0:
            obs, reward, terminated, _ = replay.post_step(held)
            obs_at_tick[n // fs] = obs
            rewards.append(float(reward))
            assert not terminated
        if n in switches:
            held = switches[n]
            replay.prepare_step(held)
        elif n % fs == 0:
            replay.prepare_step(held)
        if n < last_tick * fs:
            replay.substep()
    prev = 0
    for reply in replies:
        tick = round(reply["info"]["sim_time"] / replay.dt)
        np.testing.assert_array_equal(reply["obs"], obs_at_tick[tick])
        assert reply["reward"] == pytest.approx(sum(rewards[prev:tick]))
        assert reply["info"]["ticks_elapsed"] == tick - prev
        prev = tick
    env.close()
    replay.close()
