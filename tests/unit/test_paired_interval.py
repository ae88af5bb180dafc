"""The paired rounds' mean and interval of ``bench --train-loop`` (remoteenv.benchmarks.harness.paired_interval)."""

from __future__ import annotations

import math

import pytest

from remoteenv.benchmarks.harness import report
from remoteenv.benchmarks.harness.paired_interval import MIN_ROUNDS, paired_interval, settled
from remoteenv.benchmarks.harness.report import rounds_record
from remoteenv.benchmarks.train_loop import format_table, ratios


def test_the_mean_is_geometric_and_the_interval_holds_it():
    mean, low, high = paired_interval([0.8, 1.25, 0.8, 1.25, 1.0, 1.0])
    assert mean == pytest.approx(1.0)  # 0.8 and 1.25 cancel; an arithmetic mean would say 1.02
    assert low < 1.0 < high
    assert paired_interval([1.1] * MIN_ROUNDS) == pytest.approx((1.1, 1.1, 1.1))


def test_the_same_rounds_give_the_same_interval_and_a_wider_spread_a_wider_one():
    rounds = [0.95, 1.02, 1.08, 0.99, 1.04, 1.01, 0.97, 1.06]
    assert paired_interval(rounds) == paired_interval(list(rounds))
    _, low, high = paired_interval(rounds)
    wide = [1.0 + 3 * (x - 1.0) for x in rounds]
    _, wide_low, wide_high = paired_interval(wide)
    assert wide_low < low and wide_high > high


def test_more_rounds_of_the_same_spread_narrow_the_interval():
    rounds = [0.95, 1.05, 0.98, 1.02, 1.0]
    _, low, high = paired_interval(rounds)
    _, long_low, long_high = paired_interval(rounds * 6)
    assert long_high - long_low < (high - low) / 1.5


def test_too_few_rounds_or_a_bad_ratio_give_no_interval():
    assert paired_interval([1.0] * (MIN_ROUNDS - 1)) is None
    assert paired_interval([1.0] * (MIN_ROUNDS - 1) + [0.0]) is None
    assert paired_interval([1.0] * (MIN_ROUNDS - 1) + [math.nan]) is None
    assert paired_interval([1.0] * (MIN_ROUNDS - 1) + [math.inf]) is None


def test_a_target_is_settled_only_by_an_interval_wholly_on_one_side():
    assert settled((1.05, 1.01, 1.09), 1.0) == "met"
    assert settled((1.02, 1.0, 1.04), 1.0) == "met"
    assert settled((0.95, 0.91, 0.99), 1.0) == "missed"
    assert settled((1.01, 0.97, 1.05), 1.0) == "not settled"


def test_the_table_gives_the_interval_and_what_it_settles(monkeypatch):
    rates = [100.0, 102.0, 98.0, 101.0, 99.0, 100.0]
    rows = [
        {"name": "remoteenv", "num_envs": 16, "median": 100.0, "rates": rates},
        # Rounds a tenth either way of remoteenv's: a mean of 1.0 that no run of six can place.
        {
            "name": "EnvPool",
            "num_envs": 16,
            "median": 100.0,
            "rates": [x * y for x, y in zip(rates, [1.1, 1 / 1.1] * 3)],
        },
        {"name": "SyncVectorEnv", "num_envs": 16, "median": 62.5, "rates": [x / 1.6 for x in rates]},
    ]
    for r in rows:
        r.update(
            cpu_us_per_step=1.0,
            trainer_cpu_us_per_step=1.0,
            voluntary_switches_per_step=0.0,
            involuntary_switches_per_step=0.0,
            wall_share={"act": 0, "env_step": 0, "update": 0},
        )
    found = {r["ratio"]: r for r in ratios(rows)}
    assert found["remoteenv / SyncVectorEnv, N=16"]["paired"] == pytest.approx([1.6, 1.6, 1.6])
    mean, low, high = found["remoteenv / EnvPool, N=16"]["paired"]
    assert mean == pytest.approx(1.0) and low < 1.0 < high
    monkeypatch.setattr(report, "machine_record", lambda: {"cpus": 2, "platform": "p", "python": "3"})
    record = {"loads": [1.0], "hogs": 0, "duration_s": 1.0, "rounds": 6, "train_env": {}, "skipped": []}
    result = rounds_record(rows=rows, ratios=list(found.values()), **record)
    lines = format_table(result).splitlines()
    [envpool] = [line for line in lines if line.startswith("remoteenv / EnvPool, N=16")]
    assert f"1.00 [{low:.2f}-{high:.2f}]" in envpool
    assert envpool.endswith(">=1.0 met (3/6 rounds); by the interval: not settled")
    [sync] = [line for line in lines if line.startswith("remoteenv / SyncVectorEnv, N=16")]
    assert "1.60 [1.60-1.60]" in sync and sync.endswith(">=1.5 met (6/6 rounds); by the interval: met")
    below = dict(found["remoteenv / SyncVectorEnv, N=16"], target=2.0)
    assert settled(tuple(below["paired"]), below["target"]) == "missed"
