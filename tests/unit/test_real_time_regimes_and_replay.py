"""The fixed-step regime and the clockless replay of a real-time world, on a fake clock.

No test waits or reads the wall clock: the clock is a number the test sets
(see tests/unit/test_real_time_stepper.py, whose stand-in world is used here).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.stepping.real_time import RealTimeStepper
from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import (
    MAX_REPLAY_STEP_TICKS,
    REPLAY_OPTION,
    replay_options,
    split_replay,
)
from tests.unit.test_real_time_stepper import FRAME_SKIP, T0, FakeClock, TickWorld, run_until


def make(mode: str, world: Any = None) -> tuple[RealTimeStepper, Any, FakeClock]:
    clock = FakeClock(T0 - 1.0)
    world = world or TickWorld()
    return RealTimeStepper(world, RunOptions(real_time=True, real_time_mode=mode), clock=clock), world, clock


def begin(stepper: RealTimeStepper, clock: FakeClock, options: dict[str, Any] | None = None, seed: Any = None) -> None:
    stepper.reset(seed=seed, options=options)
    clock.t = T0
    stepper.start(T0)


def step_after(stepper: RealTimeStepper, clock: FakeClock, think_substeps: float, action: Any, seq: int) -> dict:
    """Think ``think_substeps`` substep periods after the last reply, submit ``action``, run until its reply
    (at once when the episode ended while the agent thought)."""
    run_until(stepper, clock, clock.t + think_substeps * stepper.period)
    at_once = stepper.submit(seq, action, None, None)
    if at_once is not None:
        return at_once
    got: list[Any] = []
    while not got:
        got = run_until(stepper, clock, stepper.next_deadline() or clock.t)
    return got[0][2]


def test_fixed_step_an_agent_within_a_tick_gets_one_tick_per_step_and_a_latency_of_one_tick():
    stepper, world, clock = make("fixed_step")
    begin(stepper, clock)
    assert stepper.describe()["real_time_mode"] == "fixed_step"
    previous = 0
    for k in range(6):
        # A third of a tick of thinking, counted from the reply: the action arrives mid-tick.
        reply = step_after(stepper, clock, FRAME_SKIP / 3, f"a{k}", k)
        info = reply["info"]
        assert info["ticks_elapsed"] == 1 and info["latency_ticks"] == 1.0 and not info["late"]
        assert info["action_substep"] == info["substep"] == previous + FRAME_SKIP  # at the next tick boundary
        assert reply["reward"] == float(info["substep"] // FRAME_SKIP)  # the tick just scored, with the held action
        previous = info["substep"]
    # Each action took effect exactly at a tick boundary, and only there.
    assert [(n, a) for n, a in world.applied if a is not None and str(a).startswith("a")] == [
        ((k + 1) * FRAME_SKIP, f"a{k}") for k in range(6)
    ]


def test_fixed_step_an_overrun_extends_the_step_to_the_first_boundary_after_the_action_arrives():
    stepper, world, clock = make("fixed_step")
    begin(stepper, clock)
    reply = step_after(stepper, clock, 1.5 * FRAME_SKIP, "slow", 0)
    info = reply["info"]
    assert info["ticks_elapsed"] == 2 and info["latency_ticks"] == 2.0 and info["late"]
    assert info["action_substep"] == 2 * FRAME_SKIP
    assert reply["reward"] == 1.0 + 2.0  # both ticks of the step, summed


def test_fixed_step_termination_answers_the_waiting_step_without_applying_it():
    stepper, world, clock = make("fixed_step", TickWorld(end_tick=2))
    begin(stepper, clock)
    reply = step_after(stepper, clock, 1.5 * FRAME_SKIP, "late", 0)
    assert reply["terminated"] and reply["info"]["action_substep"] is None
    assert reply["info"]["substep"] == 2 * FRAME_SKIP


def test_an_unknown_regime_is_refused():
    with pytest.raises(ValueError, match="real_time_mode must be one of"):
        make("rubber")


def schedule_of(replies: list[dict]) -> list[int]:
    return [
        r["info"]["action_substep"] if r["info"]["action_substep"] is not None else r["info"]["substep"]
        for r in replies
    ]


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_a_replay_answers_every_step_at_once_exactly_as_the_clock_did(mode):
    stepper, world, clock = make(mode, TickWorld(end_tick=9))
    begin(stepper, clock)
    thinks = [0.5, 5.2, 1.0, 9.7, 2.2, 0.1, 3.3, 7.0]
    replies = []
    for k, think in enumerate(thinks):
        reply = step_after(stepper, clock, think, f"a{k}", k)
        replies.append(reply)
        if reply["terminated"]:
            break
    real_applied = list(world.applied)

    twin, twin_world, twin_clock = make(mode, TickWorld(end_tick=9))
    twin_clock.t = 5.0  # the replay never reads its clock
    begin(twin, twin_clock, replay_options(None, mode, schedule_of(replies)))
    assert twin.next_deadline() is None  # nothing runs on a deadline
    for k, real in enumerate(replies):
        got = twin.submit(k, f"a{k}", None, None)
        assert got is not None
        for key in ("obs", "reward", "terminated"):
            assert np.array_equal(got[key], real[key]) if key == "obs" else got[key] == real[key]
        for key in ("ticks_elapsed", "substep", "action_substep", "latency_ticks", "late", "tick"):
            assert got["info"][key] == real["info"][key], key
    assert twin_world.applied == real_applied  # the same switches at the same substeps
    assert replies[-1]["terminated"]
    # Issue 35, item 4: the clock renders every tick; the replay only the ticks its replies carry.
    assert world.observed == list(range(1, 10))
    assert twin_world.observed == [r["info"]["tick"] for r in replies]


def test_a_replayed_step_may_run_at_most_max_replay_step_ticks():
    twin, _, clock = make("elastic")
    limit = MAX_REPLAY_STEP_TICKS * FRAME_SKIP
    begin(
        twin, clock, replay_options(None, "elastic", [limit, 2 * limit + FRAME_SKIP + 2])
    )  # step 0 replies at limit + FRAME_SKIP, one substep run
    assert twin.submit(0, "a", None, None) is not None  # exactly the bound
    with pytest.raises(RequestError, match=f"more than the {MAX_REPLAY_STEP_TICKS} ticks"):
        twin.submit(1, "b", None, None)


def test_a_replay_refuses_a_step_beyond_the_recording_and_a_schedule_of_another_regime():
    twin, _, clock = make("elastic")
    begin(twin, clock, replay_options({"level": 2}, "elastic", [3]))
    assert twin.submit(0, "a", None, None) is not None
    with pytest.raises(RequestError, match="beyond the recording"):
        twin.submit(1, "b", None, None)
    with pytest.raises(RequestError, match="recorded with real_time_mode='fixed_step'"):
        twin.reset(seed=None, options=replay_options(None, "fixed_step", [4]))


@pytest.mark.parametrize(
    "bad",
    [
        [],
        [3, 2],
        [-1],
        [True],
        [1.5],
        "1,2",
        [2**40],
    ],
)
def test_a_malformed_schedule_is_refused_without_echoing_it(bad):
    with pytest.raises(ValueError, match="action_substeps"):
        split_replay({REPLAY_OPTION: {"mode": "elastic", "action_substeps": bad}}, "elastic")
    with pytest.raises(ValueError, match="exactly"):
        split_replay({REPLAY_OPTION: {"mode": "elastic"}}, "elastic")


def test_the_scene_gets_the_options_without_the_replay_key():
    rest, schedule = split_replay(replay_options({"level": 2}, "elastic", [1, 5]), "elastic")
    assert rest == {"level": 2} and schedule == [1, 5]
    assert split_replay(replay_options(None, "elastic", [1]), "elastic") == (None, [1])
    assert split_replay({"level": 2}, "elastic") == ({"level": 2}, None)


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_a_real_scene_replays_bit_for_bit(mode):
    """MuJoCo CartPole: random arrival times on the clock, then the replay of their substeps."""
    rng = np.random.default_rng(7)
    env, twin_env = CartPoleEnv(continuous=True), CartPoleEnv(continuous=True)
    try:
        stepper, _, clock = make(mode, env)
        begin(stepper, clock, seed=4)
        frame_skip = env.frame_skip
        replies, actions = [], []
        for k in range(30):
            actions.append(rng.uniform(-1, 1, size=(1,)).astype(np.float32))
            replies.append(step_after(stepper, clock, rng.uniform(0, 3) * frame_skip, actions[-1], k))
            if replies[-1]["terminated"]:
                break
        assert replies[-1]["terminated"]  # random pushes topple it: the freeze is replayed too
        twin, _, twin_clock = make(mode, twin_env)
        begin(twin, twin_clock, replay_options(None, mode, schedule_of(replies)), seed=4)
        for k, (action, real) in enumerate(zip(actions, replies)):
            got = twin.submit(k, action, None, None)
            assert got is not None
            assert got["obs"].tobytes() == real["obs"].tobytes() and got["reward"] == real["reward"]
            assert got["terminated"] == real["terminated"] and got["info"]["sim_time"] == real["info"]["sim_time"]
    finally:
        env.close()
        twin_env.close()
