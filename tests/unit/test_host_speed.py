"""The host's speed around each slot of ``bench --train-loop`` (remoteenv.benchmarks.harness.host_speed)."""

from __future__ import annotations

import os

import pytest

from remoteenv.benchmarks.harness import host_speed
from remoteenv.benchmarks.harness.host_speed import FULL_SPEED, HostSpeed, probe_s
from remoteenv.benchmarks.train_loop import full_speed_rounds, ratios


def test_a_probe_times_the_loop_on_every_cpu_and_gives_the_cpus_back():
    before = os.sched_getaffinity(0)
    assert probe_s() > 0
    assert os.sched_getaffinity(0) == before


def test_a_slot_is_as_fast_as_the_slower_of_its_two_probes_against_the_runs_fastest(monkeypatch):
    times = iter([0.010, 0.010, 0.020, 0.008, 0.008])
    monkeypatch.setattr(host_speed, "probe_s", lambda: next(times))
    host = HostSpeed()  # 10 ms
    slots = [host.after_slot() for _ in range(4)]  # then 10, 20, 8 and 8 ms
    assert [host.speed(s) for s in slots] == pytest.approx([0.8, 0.4, 0.4, 1.0])


def test_only_rounds_with_both_slots_at_full_speed_count_as_such():
    a = {"host_speeds": [1.0, 0.5, 0.9, FULL_SPEED]}
    b = {"host_speeds": [0.95, 1.0, 0.6, 1.0]}
    assert full_speed_rounds(a, b, [1.1, 0.7, 0.8, 1.05]) == [1.1, 1.05]
    assert full_speed_rounds({}, b, [1.1, 0.7, 0.8, 1.05]) == []  # a result from before the probes
    assert full_speed_rounds(a, {"host_speeds": [1.0]}, [1.1, 0.7, 0.8, 1.05]) == []


def test_a_ratio_gives_its_interval_over_the_rounds_at_full_speed_too():
    slow = [1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.5]
    rows = [
        {
            "name": "remoteenv",
            "num_envs": 16,
            "median": 105.0,
            "cpu_us_per_step": 1.0,
            "rates": [105.0] * 5 + [40.0] * 2,
            "host_speeds": slow,
        },
        {
            "name": "EnvPool",
            "num_envs": 16,
            "median": 100.0,
            "cpu_us_per_step": 1.0,
            "rates": [100.0] * 7,
            "host_speeds": [1.0] * 7,
        },
    ]
    [r] = [r for r in ratios(rows) if r["ratio"] == "remoteenv / EnvPool, N=16"]
    assert r["full_speed_rounds"] == pytest.approx([1.05] * 5)
    assert r["paired_full_speed"] == pytest.approx([1.05, 1.05, 1.05])
    assert r["paired"][0] < 1.0  # the two slow rounds pull the whole run's mean below
