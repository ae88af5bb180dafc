"""Lock-step stepping: one tick per request; action_delay=k applies each action k ticks late."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from remoteenv.sim.stepping.lock_step import LockStepper, LockStepping
from remoteenv.wire.run_options.options import RunOptions

DT = 0.02


class RecordingWorld:
    """Stands in for a BaseEnv: records the action of every tick; reward = tick number."""

    def __init__(self) -> None:
        self.data = SimpleNamespace(time=0.0)
        self.dt = DT
        self.actions: list[Any] = []

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        self.data.time = 0.0
        self.actions = []
        return np.zeros(2), {"seed": seed}

    def default_action(self) -> Any:
        return None

    def step(self, action: Any) -> tuple[Any, Any, Any, dict[str, Any]]:
        self.actions.append(action)
        self.data.time = len(self.actions) * DT
        tick = len(self.actions)
        return np.full(2, tick), np.float32(tick), np.bool_(tick == 5), {"tick": tick}


def make(delay: int) -> tuple[LockStepper, RecordingWorld]:
    world = RecordingWorld()
    return LockStepper(world, RunOptions(action_delay=delay)), world  # type: ignore[arg-type]


def test_without_delay_each_action_is_applied_in_its_own_tick_and_info_is_the_scenes():
    stepper, world = make(0)
    assert not stepper.has_reset
    stepper.reset(seed=4, options=None)
    assert stepper.has_reset
    reply = stepper.submit(1, "a", None, None)
    assert world.actions == ["a"]
    assert reply == {"obs": reply["obs"], "reward": 1.0, "terminated": False, "truncated": False, "info": {"tick": 1}}
    assert type(reply["reward"]) is float and type(reply["terminated"]) is bool
    assert stepper.describe() == {"mode": "lock_step", "action_delay": 0}


@pytest.mark.parametrize("delay", [1, 3])
def test_with_delay_k_the_default_runs_k_ticks_then_each_action_k_ticks_late(delay):
    stepper, world = make(delay)
    stepper.reset(seed=None, options=None)
    sent = [f"a{t}" for t in range(6)]
    infos = [stepper.step(a)["info"] for a in sent]
    assert world.actions == [None] * delay + sent[: len(sent) - delay]
    for t, info in enumerate(infos):
        assert info["applied_action"] == (None if t < delay else sent[t - delay])
        assert info["tick"] == t + 1  # the scene's own keys stay
        assert info["sim_time"] == pytest.approx((t + 1) * DT)
        assert info["ticks_elapsed"] == 1 and info["late"] is True
        if t < delay:  # the default acts: no latency to report yet
            assert info["latency_ticks"] is None and info["latency_s"] is None
        else:  # after the fact: the action in force arrived delay ticks after the observation it answered
            assert info["latency_ticks"] == delay and info["latency_s"] == pytest.approx(delay * DT)
    assert stepper.describe() == {"mode": "lock_step", "action_delay": delay}


def test_a_reset_refills_the_delay_queue_with_the_default():
    stepper, world = make(2)
    stepper.reset(seed=None, options=None)
    for a in "xyz":
        stepper.step(a)
    stepper.reset(seed=None, options=None)
    applied = [stepper.step(a)["info"]["applied_action"] for a in "uvw"]
    assert applied == [None, None, "u"]


def test_negative_delay_is_refused():
    with pytest.raises(ValueError, match="action_delay"):
        LockStepper(RecordingWorld(), RunOptions(action_delay=-1))  # type: ignore[arg-type]


def test_lock_stepping_has_no_clock_and_one_stepper_per_world():
    stepping = LockStepping([RecordingWorld(), RecordingWorld()], RunOptions(action_delay=1))  # type: ignore[list-item]
    assert stepping.next_deadline() is None and not stepping.clock_waiting
    assert list(stepping.run_due(0.0)) == []
    assert [w.action_delay for w in stepping.worlds] == [1, 1]
    assert stepping.worlds[0].env is not stepping.worlds[1].env
