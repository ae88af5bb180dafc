"""The adaptive hot-wait policy (wait hot while the peer has been quick)."""

from __future__ import annotations

import pytest

from remoteenv.wire import hot_wait
from remoteenv.wire.hot_wait import HotWait


@pytest.fixture(autouse=True)
def two_cpus(monkeypatch):
    monkeypatch.delenv("REMOTEENV_NO_SPIN", raising=False)
    monkeypatch.setattr(hot_wait.os, "cpu_count", lambda: 2)


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
    monkeypatch.setattr(hot_wait.os, "cpu_count", lambda: 1)
    assert HotWait(1e-3).window_s == 0.0
    monkeypatch.setattr(hot_wait.os, "cpu_count", lambda: 2)
    monkeypatch.setenv("REMOTEENV_NO_SPIN", "1")
    single = HotWait(1e-3)
    assert single.window_s == 0.0 and not single.worth_it()
