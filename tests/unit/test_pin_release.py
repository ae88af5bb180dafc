"""A pinned sim takes its CPUs back when a window of answers shows it
waited for its CPU at least OFF_CPU_S and longer than it ran; never while it
is not pinned, never on a window that says less, never where the kernel
does not say (the figures are the kernel's, fed here by hand). Released, it
tries its CPU again after RETRY_S, waiting twice as long after each trial a
busy neighbour ends, and leaves a sim someone else placed meanwhile alone."""

from __future__ import annotations

import time

import pytest

from remoteenv.sim.process import pin_release
from remoteenv.sim.process.pin_release import MAX_RETRY_S, OFF_CPU_S, RETRY_S, TRIAL_WINDOWS, WINDOW, PinRelease


class FakeStat:
    """``schedstat`` as a test sets it: (seconds run, seconds waited)."""

    def __init__(self) -> None:
        self.ran = self.waited = 0.0
        self.reads = 0
        self.known = True
        self.closed = False

    def read(self):
        self.reads += 1
        return (self.ran, self.waited) if self.known else None

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def cpus(monkeypatch):
    """The sim's affinity, and the calls that set it."""
    state = {"now": {0, 1, 2, 3}, "set": []}
    monkeypatch.setattr(pin_release, "_affinity", lambda: set(state["now"]))

    def set_affinity(pid, cpus):
        assert pid == 0
        state["set"].append(set(cpus))
        state["now"] = set(cpus)

    monkeypatch.setattr(pin_release.os, "sched_setaffinity", set_affinity)
    return state


def _window(watch: PinRelease) -> None:
    for _ in range(WINDOW):
        watch.answered()


def test_an_unpinned_sim_reads_nothing_and_changes_nothing(cpus):
    stat = FakeStat()
    watch = PinRelease(0, stat)
    for _ in range(3):
        stat.waited += 1.0
        _window(watch)
    assert stat.reads == 0 and cpus["set"] == [] and not watch.released


def test_a_pinned_sim_kept_off_its_cpu_takes_its_cpus_back_once(cpus):
    stat = FakeStat()
    watch = PinRelease(3, stat)
    cpus["now"] = {1}  # the agent pinned it
    _window(watch)  # the first window only reads where the figures stand
    stat.ran += 0.004
    stat.waited += OFF_CPU_S
    _window(watch)
    assert cpus["set"] == [{0, 1, 2, 3}] and watch.released and watch.pinned_cpus == {1}
    cpus["now"] = {2}  # pinned again by someone else: the sim does not fight it
    stat.waited += 1.0
    _window(watch)
    _window(watch)
    assert cpus["set"] == [{0, 1, 2, 3}]


def test_windows_that_say_less_keep_the_sim_pinned(cpus):
    stat = FakeStat()
    watch = PinRelease(0, stat)
    cpus["now"] = {0}
    _window(watch)
    stat.ran += 0.001
    stat.waited += OFF_CPU_S * 0.9  # longer than it ran, but little
    _window(watch)
    stat.ran += OFF_CPU_S * 3
    stat.waited += OFF_CPU_S * 2  # much, but it ran longer
    _window(watch)
    stat.ran += 0.001
    stat.waited += 1.0  # only part of a window: judged at its end
    for _ in range(WINDOW - 1):
        watch.answered()
    assert cpus["set"] == [] and not watch.released
    watch.answered()
    assert cpus["set"] == [{0, 1, 2, 3}]


def test_where_the_kernel_does_not_say_nothing_changes(cpus):
    stat = FakeStat()
    stat.known = False
    watch = PinRelease(0, stat)
    cpus["now"] = {0}
    for _ in range(3):
        stat.waited += 1.0
        _window(watch)
    assert cpus["set"] == [] and not watch.released


def test_the_watched_answer_counts_even_when_it_raises(cpus):
    stat = FakeStat()
    watch = PinRelease(0, stat)
    cpus["now"] = {0}
    calls = []

    def answer(channel, frames):
        calls.append((channel, frames))
        raise RuntimeError("boom")

    watched = watch.watching(answer)
    for _ in range(WINDOW):
        with pytest.raises(RuntimeError):
            watched("pipe", [])
    assert len(calls) == WINDOW and stat.reads == 1


def test_the_kernels_figures_of_this_thread_are_read():
    stat = pin_release.SchedStat()
    try:
        first = stat.read()
        if first is None:
            pytest.skip("this kernel has no schedstat")
        # The kernel books a running thread's time at its ticks and switches, so
        # run long enough for several ticks (at HZ = 100, 5): a few ms may show nothing.
        started = time.thread_time()
        while time.thread_time() - started < 0.05:
            sum(range(10_000))
        second = stat.read()
        assert second is not None and second[0] > first[0] and second[1] >= first[1]
    finally:
        stat.close()


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _released(cpus, stat: FakeStat, clock: Clock) -> PinRelease:
    """A sim pinned to CPU 1 that a busy neighbour made take its CPUs back."""
    watch = PinRelease(0, stat, clock)
    cpus["now"] = {1}
    _window(watch)
    _busy(stat)
    _window(watch)
    assert watch.released and cpus["now"] == {0, 1, 2, 3}
    return watch


def _busy(stat: FakeStat) -> None:
    stat.ran += 0.001
    stat.waited += OFF_CPU_S * 2


def _quiet(stat: FakeStat) -> None:
    stat.ran += 0.010
    stat.waited += 0.0001


def test_a_released_sim_tries_its_cpu_again_and_keeps_it_when_the_neighbour_left(cpus):
    stat, clock = FakeStat(), Clock()
    watch = _released(cpus, stat, clock)
    clock.now += RETRY_S * 0.9
    _window(watch)
    assert watch.released and cpus["now"] == {0, 1, 2, 3}  # not yet
    clock.now += RETRY_S * 0.2
    _window(watch)
    assert not watch.released and cpus["now"] == {1}  # pinned again, as the agent had it
    _window(watch)  # the first window pinned again only reads
    for _ in range(TRIAL_WINDOWS + 3):
        _quiet(stat)
        _window(watch)
    assert not watch.released and cpus["set"] == [{0, 1, 2, 3}, {1}] and not stat.closed


def test_a_trial_a_busy_neighbour_ends_doubles_the_wait_up_to_its_bound(cpus):
    stat, clock = FakeStat(), Clock()
    watch = _released(cpus, stat, clock)
    waits = []
    for _ in range(8):
        released_at = clock.now
        while watch.released:
            clock.now += 0.25
            _window(watch)
        waits.append(clock.now - released_at)
        _window(watch)  # reads where the figures stand
        _busy(stat)
        _window(watch)  # the neighbour is still there
        assert watch.released and cpus["now"] == {0, 1, 2, 3}
    expected = [min(RETRY_S * 2**i, MAX_RETRY_S) for i in range(8)]
    assert all(abs(w - e) <= 0.25 for w, e in zip(waits, expected)), waits
    # A trial that lasts: the next release waits RETRY_S again.
    while watch.released:
        clock.now += 0.25
        _window(watch)
    _window(watch)
    for _ in range(TRIAL_WINDOWS):
        _quiet(stat)
        _window(watch)
    _busy(stat)
    _window(watch)
    released_at = clock.now
    while watch.released:
        clock.now += 0.25
        _window(watch)
    assert abs(clock.now - released_at - RETRY_S) <= 0.25


def test_a_sim_someone_else_placed_meanwhile_is_left_alone(cpus):
    stat, clock = FakeStat(), Clock()
    watch = _released(cpus, stat, clock)
    cpus["now"] = {2, 3}  # the user's own placement
    clock.now += MAX_RETRY_S * 2
    for _ in range(3):
        _window(watch)
    assert cpus["now"] == {2, 3} and watch.pinned_cpus is None and stat.closed


def test_a_sim_the_os_will_not_move_stays_where_it_is_and_tries_no_more(cpus, monkeypatch):
    stat, clock = FakeStat(), Clock()
    watch = PinRelease(0, stat, clock)
    cpus["now"] = {1}
    _window(watch)

    def refuse(pid, cpus_):
        raise PermissionError("not allowed")

    monkeypatch.setattr(pin_release.os, "sched_setaffinity", refuse)
    _busy(stat)
    _window(watch)
    clock.now += MAX_RETRY_S * 2
    _window(watch)
    assert cpus["now"] == {1} and watch.pinned_cpus is None and stat.closed
