"""The host's steal time around each slot of ``bench --train-loop`` (remoteenv.benchmarks.harness.host_steal)."""

from __future__ import annotations

import os
import time

import pytest

from remoteenv.benchmarks.harness import report
from remoteenv.benchmarks.harness.host_steal import HostSteal, cpu_times, share
from remoteenv.benchmarks.harness.report import rounds_record
from remoteenv.benchmarks.train_loop import format_table, full_speed_rounds


def _stat(path, user: int, idle: int, steal: int) -> None:
    # user nice system idle iowait irq softirq steal guest guest_nice
    path.write_text(f"cpu  {user} 0 10 {idle} 0 0 0 {steal} 7 0\ncpu0 1 2 3 4 5 6 7 8 9 10\n")


def test_a_slots_share_is_the_steal_over_all_cpu_time_that_passed(tmp_path):
    stat = tmp_path / "stat"
    _stat(stat, user=100, idle=500, steal=10)
    steal = HostSteal(str(stat))
    steal.start()
    _stat(stat, user=160, idle=520, steal=30)  # 60 + 20 + 20 ticks passed, 20 of them stolen
    assert steal.stop() == pytest.approx(0.2)
    assert cpu_times(str(stat)) == (30, 160 + 10 + 520 + 30)  # guest time is within user already


def test_no_counters_or_no_time_passed_gives_none(tmp_path):
    assert cpu_times(str(tmp_path / "absent")) is None
    bad = tmp_path / "bad"
    bad.write_text("intr 1 2 3\n")
    assert cpu_times(str(bad)) is None
    assert share(None, (1, 2)) is None and share((1, 2), None) is None
    assert share((5, 100), (5, 100)) is None


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="/proc/stat is Linux's")
def test_the_real_counters_give_a_share_between_zero_and_one():
    steal = HostSteal()
    steal.start()
    got = None
    for _ in range(1_000):  # until the kernel's counters have moved on by a tick (10 ms at most, usually)
        time.sleep(0.002)
        got = steal.stop()
        if got is not None:
            break
    assert got is not None and 0.0 <= got <= 1.0


def test_the_report_names_the_runs_steal_and_the_slots_that_met_much_of_it(monkeypatch):
    row = {
        "name": "remoteenv",
        "num_envs": 16,
        "median": 1.0,
        "rates": [1.0, 1.0, 1.0],
        "host_speeds": [1.0, 1.0, 1.0],
        "host_steals": [0.0, 0.12, None],
        "cpu_us_per_step": 1.0,
        "trainer_cpu_us_per_step": 1.0,
        "voluntary_switches_per_step": 0.0,
        "involuntary_switches_per_step": 0.0,
        "wall_share": {"act": 0.3, "env_step": 0.4, "update": 0.3},
    }
    monkeypatch.setattr(report, "machine_record", lambda: {"cpus": 2, "platform": "x", "python": "3"})
    record = {"loads": [1.0], "hogs": 0, "duration_s": 1.0, "rounds": 3, "train_env": {}, "skipped": []}
    text = format_table(rounds_record(rows=[row], ratios=[], **record))
    assert "held 0%-12% of the CPUs' time in a slot" in text and "1 of 2 slots at 5% or more" in text


def test_rounds_met_by_the_hosts_steal_do_not_count_as_at_full_speed():
    a = {"host_speeds": [1.0] * 4, "host_steals": [0.0, 0.30, 0.01, None]}
    b = {"host_speeds": [1.0] * 4, "host_steals": [0.02, 0.0, 0.06, 0.0]}
    assert full_speed_rounds(a, b, [1.1, 0.5, 0.9, 1.05]) == [1.1, 1.05]
    # Rows of a run before the steal was measured: the probes alone decide.
    assert full_speed_rounds({"host_speeds": [1.0, 1.0]}, {"host_speeds": [1.0, 0.5]}, [1.1, 0.9]) == [1.1]
