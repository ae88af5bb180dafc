"""The adaptive hot-wait policy (wait hot while the peer has been quick)."""

from __future__ import annotations

import pytest
from fakes import hot_waits_allowed

from remoteenv.wire.shared_memory import hot_wait
from remoteenv.wire.shared_memory.hot_wait import HotWait


@pytest.fixture(autouse=True)
def two_cpus(monkeypatch):
    hot_waits_allowed(monkeypatch)


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


def test_patience_keeps_waiting_hot_through_fewer_late_waits_in_a_row_than_it_allows():
    hot = HotWait(1e-3, patience=3)
    for _ in range(2):
        hot.waited(5e-3)
        assert hot.worth_it()  # one or two late waits in a row: still hot
    hot.waited(0.5e-3)  # a quick one starts the count again
    hot.waited(5e-3)
    hot.waited(5e-3)
    assert hot.worth_it()
    hot.waited(5e-3)  # the third late wait in a row: as slow a peer as patience allows
    answers = [hot.worth_it() for _ in range(32)]
    assert answers.count(True) == 1 and answers[31]  # cold, probing every 32 waits
    hot.waited(0.1e-3)
    assert hot.worth_it()


def test_the_default_patience_goes_cold_after_one_late_wait_and_patience_counts_waits():
    hot = HotWait(1e-3)
    assert hot.patience == 1
    hot.waited(5e-3)
    assert not hot.worth_it()
    with pytest.raises(ValueError, match="at least 1"):
        HotWait(1e-3, patience=0)


def test_disabled_by_a_zero_window_one_cpu_or_the_environment(monkeypatch):
    assert not HotWait(0.0).worth_it()
    monkeypatch.setattr(hot_wait, "usable_cpus", lambda: 1)
    assert HotWait(1e-3).window_s == 0.0
    monkeypatch.setattr(hot_wait, "usable_cpus", lambda: 2)
    monkeypatch.setenv("REMOTEENV_NO_SPIN", "1")
    single = HotWait(1e-3)
    assert single.window_s == 0.0 and not single.worth_it()


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch):
    fake = FakeClock()
    monkeypatch.setattr(hot_wait.time, "perf_counter", fake)
    monkeypatch.setattr(hot_wait, "yield_cpu", lambda: None)
    return fake


def test_a_spin_goes_on_in_short_steps_until_its_window_ends(clock):
    hot = HotWait(1e-3)
    assert hot.worth_it()
    for _ in range(9):
        clock.now += 1e-4  # polled every 0.1 ms: never kept off the CPU for long
        assert hot.spin()
    clock.now += 1.5e-4
    assert not hot.spin()  # 1.05 ms: the window is over
    assert hot.worth_it()  # a window ending is no stall: the next wait may go hot


def test_a_stalled_spin_stops_and_every_hot_wait_of_the_process_sleeps_for_a_while(clock):
    hot, other = HotWait(1.0), HotWait(1.0)
    assert hot.worth_it()
    clock.now += hot_wait.STALL_S * 1.5  # kept off the CPU by a busy neighbour
    assert not hot.spin()
    assert not hot.worth_it() and not other.worth_it()
    clock.now += hot_wait.COOL_DOWN_S * 1.01
    assert hot.worth_it() and other.worth_it()  # then they try again


def _stall(hot: HotWait, clock: FakeClock) -> None:
    """Start a hot wait on ``hot`` and keep it off the CPU past the stall limit."""
    assert hot.worth_it()
    clock.now += hot_wait.STALL_S * 1.5
    assert not hot.spin()


def _cool_down(hot: HotWait, clock: FakeClock) -> float:
    """How long (seconds, to 1 ms) hot waits stay off after the stall just seen."""
    start, waited = clock.now, 0.0
    while not hot.worth_it():
        clock.now += 1e-3
        waited = clock.now - start
    return round(waited, 3)


def test_a_lone_stall_cools_down_briefly_and_stalls_in_a_row_ever_longer_up_to_the_limit(clock):
    hot = HotWait(1.0)
    _stall(hot, clock)
    assert _cool_down(hot, clock) == pytest.approx(hot_wait.COOL_DOWN_MIN_S, abs=2e-3)  # e.g. one garbage collection
    lengths = []
    for _ in range(8):  # a busy neighbour: the first spin after each cool-down stalls again
        _stall(hot, clock)
        lengths.append(_cool_down(hot, clock))
    assert lengths[0] == pytest.approx(2 * hot_wait.COOL_DOWN_MIN_S, abs=2e-3)
    assert lengths == sorted(lengths) and lengths[-1] == pytest.approx(hot_wait.COOL_DOWN_S, abs=2e-3)
    assert lengths[-2] == pytest.approx(hot_wait.COOL_DOWN_S, abs=2e-3)  # stays at the limit while the stalls go on
    clock.now += hot_wait.STALL_MEMORY_S  # then a quiet spell: the next lone stall is brief again
    _stall(hot, clock)
    assert _cool_down(hot, clock) == pytest.approx(hot_wait.COOL_DOWN_MIN_S, abs=2e-3)


def test_begin_starts_a_window_whatever_the_last_waits_took_unless_spinning_is_off(clock, monkeypatch):
    hot = HotWait(1e-3)
    hot.waited(5e-3)  # slow waits make worth_it() say no...
    assert not hot.worth_it()
    assert hot.allowed() and hot.begin()  # ...but a wait the peer said is due may still go hot
    clock.now += 0.5e-3
    assert hot.spin()
    clock.now += 0.6e-3
    assert not hot.spin()  # its window, from begin()
    assert hot.begin()
    clock.now += hot_wait.STALL_S * 1.5  # kept off the CPU while it spun
    assert not hot.spin()  # a stall: the process cools down...
    assert not hot.allowed() and not hot.begin()  # ...begin() included
    monkeypatch.setenv("REMOTEENV_NO_SPIN", "1")
    assert not HotWait(1e-3).begin()
