"""The adaptive hot-wait policy (wait hot while the peer has been quick)."""

from __future__ import annotations

import pytest

from remoteenv.wire import hot_wait
from remoteenv.wire.hot_wait import HotWait
from remoteenv.wire.hot_wait import runnable_tasks as host_runnable_tasks


@pytest.fixture(autouse=True)
def two_cpus(monkeypatch):
    monkeypatch.delenv("REMOTEENV_NO_SPIN", raising=False)
    monkeypatch.setattr(hot_wait, "_usable_cpus", lambda: 2)
    monkeypatch.setattr(hot_wait, "_HOST_CPUS", 2)
    monkeypatch.setattr(hot_wait, "runnable_tasks", lambda: 1)


def test_waits_hot_while_the_peer_answers_within_the_window():
    hot = HotWait(1e-3)
    assert hot.worth_it()  # nothing measured yet
    hot.waited(0.5e-3)
    assert hot.worth_it()
    hot.waited(1e-3)
    assert hot.worth_it()  # the window itself still counts as quick


def test_stops_when_the_peer_is_slow_and_probes_every_32_waits():
    hot = HotWait(1e-3)
    hot.waited(5e-3)
    answers = [hot.worth_it() for _ in range(64)]
    assert answers.count(True) == 2 and answers[31] and answers[63]
    hot.waited(0.1e-3)  # a probe found the peer quick again
    assert hot.worth_it()


def test_disabled_by_a_zero_window_one_cpu_or_the_environment(monkeypatch):
    assert not HotWait(0.0).worth_it()
    monkeypatch.setattr(hot_wait, "_usable_cpus", lambda: 1)
    assert HotWait(1e-3).window_s == 0.0
    monkeypatch.setattr(hot_wait, "_usable_cpus", lambda: 2)
    monkeypatch.setenv("REMOTEENV_NO_SPIN", "1")
    single = HotWait(1e-3)
    assert single.window_s == 0.0 and not single.worth_it()


def test_no_hot_wait_while_more_tasks_are_runnable_than_cpus(monkeypatch):
    hot = HotWait(1e-3)
    monkeypatch.setattr(hot_wait, "runnable_tasks", lambda: 3)  # a hog beside two peers
    assert not hot.worth_it()
    monkeypatch.setattr(hot_wait, "runnable_tasks", lambda: 2)
    assert hot.worth_it()


def test_a_spin_stops_when_contention_appears(monkeypatch):
    running = [2]
    monkeypatch.setattr(hot_wait, "runnable_tasks", lambda: running[0])
    monkeypatch.setattr(hot_wait, "_CONTENTION_CHECK_S", 0.0)
    hot = HotWait(10.0)
    assert hot.worth_it()
    assert hot.spin() and hot.spin()
    running[0] = 3  # the peer woke up and has no CPU to run on
    assert not hot.spin()


def test_a_spin_stops_at_the_end_of_its_window():
    hot = HotWait(1e-3)
    assert hot.worth_it()
    spins = 0
    while hot.spin():
        spins += 1
        assert spins < 10_000_000
    assert not hot.spin()


def test_the_host_run_queue_is_read_where_linux_reports_it():
    if hot_wait._LOADAVG_FD is None:
        pytest.skip("no /proc/loadavg on this platform")
    running = host_runnable_tasks()
    assert running is not None and running >= 1  # this test itself is running
