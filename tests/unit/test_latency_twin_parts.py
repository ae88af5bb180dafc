"""The lock-step twin's parts without processes: latencies to countdowns and
back, the trace file, the recorder and the replay over stand-in envs, and
the return comparison."""

from __future__ import annotations

import os
import stat
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.delays import Trace
from remoteenv.latency.twin import (
    LatencyRecorder,
    LockStepTwin,
    compare_returns,
    decision_ticks,
    load_recording,
    make_twin,
    twin_latency,
    twin_values,
)
from remoteenv.latency.twin.compare import ks_distance
from remoteenv.latency.twin.trace import write_trace_file


def test_a_latency_becomes_whole_ticks_by_the_documented_rounding():
    # ticks_elapsed = floor(latency) + 1 for an action that took effect
    assert twin_latency(3, 2.3, "floor") == 2 and twin_latency(3, 2.3, "nearest") == 2
    assert twin_latency(3, 2.5, "floor") == 2 and twin_latency(3, 2.5, "nearest") == 3  # halves go up
    assert twin_latency(3, 2.4999999999, "nearest") == 3  # sim times are sums of floats
    assert twin_latency(1, 0.1, "nearest") == 0 and twin_latency(1, 0.9, "nearest") == 1
    assert twin_latency(4, None) == 4  # never took effect: due one tick after the end
    with pytest.raises(ValueError):
        twin_latency(0, 0.5)
    with pytest.raises(ValueError):
        twin_latency(2, 1.5, "ceil")


def test_each_step_becomes_a_countdown_to_the_tick_its_action_is_due():
    assert twin_values([3, 1, 2], [2.2, 0.1, 1.0], "floor") == [2, 1, 0, 0, 1, 0]
    assert twin_values([3, 2], [2.7, 1.2], "nearest") == [3, 2, 1, 1, 0]
    # A countdown ending at 1 before one starting at 0 is raised by a tick (its action is overtaken either way).
    assert twin_values([2, 1, 1], [1.6, 0.3, 0.2], "nearest") == [3, 2, 0, 0]
    assert decision_ticks([3, 2, 0, 0]) == [2, 1, 1]
    assert twin_values([2, 3], [1.2, None]) == [1, 0, 3, 2, 1]


def test_the_holds_read_back_from_the_values_are_the_recorded_steps():
    rng = np.random.default_rng(0)
    for _ in range(300):
        n = int(rng.integers(1, 30))
        ticks = rng.integers(1, 6, size=n).tolist()
        latency: list[float | None] = [t - 1 + float(rng.uniform(0.05, 0.95)) for t in ticks]
        if rng.random() < 0.3:
            latency[-1] = None  # the episode ended while the agent thought
        for rounding in ("nearest", "floor"):
            values = twin_values(ticks, latency, rounding)
            assert len(values) == sum(ticks) and decision_ticks(values) == ticks
            start = 0
            for t, lat in zip(ticks, latency):  # every copy of a step's action is due at the same tick
                assert len({start + i + v for i, v in enumerate(values[start : start + t])}) == 1
                top = twin_latency(t, lat, rounding)
                if values[start] != top:  # raised by one: it ended at 1 and the next step's action is due then
                    assert values[start] == top + 1 and top - t + 1 == 1 and values[start + t] == 0
                start += t


def test_the_trace_file_is_a_plain_trace_with_one_line_per_step(tmp_path):
    values = twin_values([2, 1, 3], [1.2, 0.4, 2.9], "nearest")
    path = write_trace_file(tmp_path / "ep.trace.txt", values, ["a header", "second line"])
    assert Trace(path) == Trace(values)
    lines = open(path).read().splitlines()
    assert lines[:2] == ["# a header", "# second line"] and lines[2:] == ["1 0", "0", "3 2 1"]
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o644
    with pytest.raises(ValueError, match="1..100000"):
        write_trace_file(tmp_path / "big.txt", [0] * 100_001)


class RealTimeStandIn(gym.Env):
    """Replies as a real-time sim does: ``ticks_elapsed``/``latency_ticks`` from a script."""

    observation_space = spaces.Box(-1, 1, (1,))
    action_space = spaces.Box(-1, 1, (1,))

    def __init__(self, script: list[tuple[int, float | None]], end_after: int) -> None:
        self.script, self.end_after, self.n = script, end_after, 0
        self.resets: list[int | None] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        self.resets.append(seed)
        self.n = 0
        return np.zeros(1, np.float32), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        ticks, latency = self.script[self.n % len(self.script)]
        self.n += 1
        info = {"ticks_elapsed": ticks, "latency_ticks": latency, "action_sim_time": None if latency is None else 1.0}
        return np.zeros(1, np.float32), float(ticks), self.n == self.end_after, False, info


def test_the_recorder_keeps_each_episode_with_the_seed_that_reproduces_its_start(tmp_path):
    rec = LatencyRecorder(RealTimeStandIn([(2, 1.3), (1, 0.6), (3, None)], end_after=3))
    for seed in (5, None, None):
        rec.reset(seed=seed)
        done = False
        while not done:
            *_, terminated, truncated, _ = rec.step(np.zeros(1, np.float32))
            done = terminated or truncated
    rec.reset(seed=9)
    rec.step(np.zeros(1, np.float32))
    rec.reset()  # cuts the episode of seed 9 short
    assert [(e.seed, e.resets_after_seed) for e in rec.episodes] == [(5, 0), (5, 1), (5, 2), (9, 0)]
    first = rec.episodes[0]
    assert first.terminated and first.steps == 3 and first.ticks == 6 and first.episode_return == 6.0
    assert first.values() == [1, 0, 1, 3, 2, 1]  # nearest: 1.3 -> 1, 0.6 -> 1, then never applied
    assert first.values("floor") == [1, 0, 0, 3, 2, 1]
    assert not rec.episodes[3].terminated and not rec.episodes[3].truncated
    summary = first.summary()
    assert summary["unapplied_steps"] == 1 and summary["late_steps"] == 2
    assert summary["mean_latency_ticks"] == pytest.approx(0.95) and summary["mean_twin_latency_ticks"] == 1.0
    path = rec.save_trace(tmp_path / "ep.txt", 0)  # the plain trace: save() now writes a recording
    assert Trace(path) == first.trace()
    loaded, env_id = load_recording(rec.save(tmp_path / "ep.json", 0))
    assert loaded == first and env_id == "RealTimeStandIn"
    # This stand-in reports no substeps, so the exact twin refuses the episode, saying why (before any sim starts).
    assert "no substep" in str(first.unreplayable)
    with pytest.raises(ValueError, match="cannot be replayed exactly: .*no substep"):
        make_twin("remoteenv/CartPole-v0", tmp_path / "ep.json")
    with pytest.raises(RuntimeError, match="reset"):
        LatencyRecorder(RealTimeStandIn([(1, 0.5)], 1)).step(np.zeros(1, np.float32))


class LockStepStandIn(gym.Env):
    """A lock-step env: one tick per step, reward 1, terminates at tick ``end``; counts its steps."""

    observation_space = spaces.Box(-np.inf, np.inf, (1,))
    action_space = spaces.Box(-1, 1, (1,))

    def __init__(self, end: int = 10**9) -> None:
        self.end, self.tick, self.dt = end, 0, 0.02
        self.actions: list[float] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        self.tick = 0
        return np.zeros(1, np.float32), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self.tick += 1
        self.actions.append(float(action[0]))
        return np.array([self.tick], np.float32), 1.0, self.tick >= self.end, False, {"tick": self.tick}


def test_the_twin_holds_each_decision_for_its_recorded_ticks_and_wraps_beyond_the_recording():
    trace = Trace([2, 1, 0, 0, 1, 0])  # steps of 3, 1 and 2 ticks
    inner = LockStepStandIn()
    twin = LockStepTwin(inner, trace, max_steps=5)
    twin.reset(seed=1)
    got = []
    for j in range(5):
        obs, reward, terminated, truncated, info = twin.step(np.array([j], np.float32))
        got.append((info["ticks_elapsed"], reward, info["latency_ticks"], info["twin_beyond_recording"], truncated))
        end = int(obs[0])
        assert end == twin.ticks and [t["tick"] for t in twin.last_ticks] == list(
            range(end - info["ticks_elapsed"] + 1, end + 1)
        )
    assert got == [
        (3, 3.0, 2, False, False),
        (1, 1.0, 0, False, False),
        (2, 2.0, 1, False, False),
        (3, 3.0, 2, True, False),  # the trace wrapped around
        (1, 1.0, 0, True, True),  # the time limit in steps
    ]
    assert inner.actions == [0, 0, 0, 1, 2, 2, 3, 3, 3, 4]
    with pytest.raises(ValueError, match="seeded reset"):
        twin.reset()
    twin.reset(seed=2)
    assert twin.ticks == 0 and twin.step(np.zeros(1, np.float32))[4]["ticks_elapsed"] == 3


def test_an_episode_that_ends_mid_hold_ends_the_step():
    twin = LockStepTwin(LockStepStandIn(end=2), Trace([3, 2, 1, 0]))
    twin.reset(seed=0)
    _, reward, terminated, truncated, info = twin.step(np.zeros(1, np.float32))
    assert (reward, terminated, truncated, info["ticks_elapsed"], info["late"]) == (2.0, True, False, 2, True)
    # The action was due at tick 4 and never landed: its latency is not known, so none is reported.
    assert info["latency_ticks"] is None and info["latency_s"] is None


def test_the_comparison_tells_equivalent_different_and_inconclusive_apart():
    rng = np.random.default_rng(3)
    real = rng.uniform(100, 500, size=40)
    same = compare_returns(real, real)
    assert same["verdict"] == "equivalent" and same["match"] and same["equal_pairs"] == 40 and same["ks_distance"] == 0
    shifted = compare_returns(real, real * 0.5)
    assert shifted["verdict"] == "different" and not shifted["match"] and shifted["ci"][1] < 0
    noisy = compare_returns(real[:4], real[:4] + rng.normal(0, 300, size=4))
    assert noisy["verdict"] == "inconclusive"
    close = compare_returns(real, real + rng.normal(0, 5, size=40))
    assert close["verdict"] == "equivalent" and close["tolerance"] == pytest.approx(0.1 * real.mean())
    assert ks_distance([1, 2, 3], [4, 5, 6]) == 1.0 and ks_distance([1, 2], [2, 1]) == 0.0
    with pytest.raises(ValueError):
        compare_returns([1.0], [1.0])
