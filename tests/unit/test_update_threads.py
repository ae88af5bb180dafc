"""Torch's threads for the learner's update (remoteenv.agent.vector.update_threads):
the update is the long think after as many steps as the last two rollouts;
torch gets its threads back for it only when that measured faster, the sims
are told (AGENT_AWAY), and the next step lowers them and ends the idle
threads' spin. A user's own thread count ends it; so does nothing else."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from fakes import FakeTorch, fake_torch_on

from remoteenv.agent.vector import torch_threads, update_threads
from remoteenv.agent.vector.torch_threads import TorchThreads, TorchThreadsNotice
from remoteenv.agent.vector.update_threads import LONG_THINK_S, MARGIN, RETRY_EVERY, UpdateThreads


class Loop:
    """A training loop's calls into the env, on a fake clock: rollouts of ``length``
    steps (think ``act_s`` each), then an update that takes ``update_s`` on one
    thread and ``update_s * speedup`` on two."""

    def __init__(self, length: int = 4, update_s: float = 0.05, speedup: float = 0.5) -> None:
        self.now = 0.0
        self.torch = FakeTorch(1)
        self.pauses = 0
        self.aways = 0
        self.length, self.update_s, self.speedup = length, update_s, speedup
        self.busy = False
        self.threads = UpdateThreads(
            self.torch, 1, 2, self._pause, self._away, clock=lambda: self.now, busy=lambda: self.busy
        )
        self.update_threads: list[int] = []  # torch's threads during each update

    def _pause(self) -> None:
        self.pauses += 1

    def _away(self) -> None:
        self.aways += 1

    def step(self) -> None:
        self.threads.step_starts()
        self.now += 300e-6  # the vector step
        self.threads.step_returns()

    def rollout(self, act_s: float = 250e-6) -> None:
        for _ in range(self.length):
            self.now += act_s
            self.step()
        threads = self.torch.get_num_threads()
        self.update_threads.append(threads)
        self.now += self.update_s * (self.speedup if threads == 2 else 1.0)


def test_the_update_is_predicted_from_two_rollouts_and_timed_both_ways_first() -> None:
    loop = Loop()
    for _ in range(6):
        loop.rollout()
    # Two rollouts to learn the length, then one update on one thread and one
    # on two (the trials), taking turns until each way has two.
    assert loop.update_threads == [1, 1, 1, 2, 1, 2]
    assert loop.aways == 2  # the sims are told exactly when torch has its threads back
    assert loop.pauses == 1  # and the step after a raise stops the idle threads' spin
    assert loop.torch.calls == [2, 1, 2]
    loop.rollout()
    assert loop.pauses == 2 and loop.torch.calls == [2, 1, 2, 1, 2]
    assert loop.update_threads[-1] == 2 and loop.torch.threads == 2  # faster: kept
    loop.step()
    assert loop.torch.threads == 1  # the next step starts on one thread


def test_two_threads_are_kept_only_if_faster_by_the_margin_and_the_other_way_is_retried() -> None:
    loop = Loop(speedup=MARGIN + 0.01)  # barely faster: not worth it
    for _ in range(6 + RETRY_EVERY):
        loop.rollout()
    chosen = loop.update_threads[6:]
    assert chosen.count(2) == 1 and chosen.count(1) == RETRY_EVERY - 1  # one retry of the way not chosen
    fast = Loop(speedup=0.6)
    for _ in range(6 + RETRY_EVERY):
        fast.rollout()
    assert fast.update_threads[6:].count(1) == 1  # and the same the other way round


def test_without_a_steady_rollout_length_nothing_is_raised() -> None:
    loop = Loop()
    for length in np.random.default_rng(0).permutation(np.arange(3, 15)).tolist():
        loop.length = length  # never the same twice in a row
        loop.rollout()
    assert loop.torch.calls == [] and loop.aways == 0


def test_short_thinks_do_not_end_a_rollout() -> None:
    loop = Loop()
    for _ in range(8):
        loop.rollout(act_s=LONG_THINK_S / 2)
    assert 2 in loop.update_threads  # still predicted: acts are not updates


def test_a_user_who_sets_torchs_threads_ends_it() -> None:
    loop = Loop()
    for _ in range(4):
        loop.rollout()
    assert loop.torch.threads == 2  # raised for the 4th update, until the next step
    loop.torch.threads = 3  # the user's own choice during their update
    loop.step()
    assert not loop.threads.active and loop.torch.threads == 3
    for _ in range(6):
        loop.rollout()
    assert loop.torch.threads == 3 and loop.aways == 1


def test_nothing_is_raised_or_timed_beside_a_busy_neighbour() -> None:
    loop = Loop()
    loop.busy = True
    for _ in range(8):
        loop.rollout()
    assert loop.torch.calls == [] and loop.aways == 0 and loop.threads.timings.predicted == 0
    loop.busy = False  # the neighbour has gone: the trials start
    for _ in range(2):
        loop.rollout()
    assert loop.update_threads[-2:] == [1, 2]


def test_a_reset_or_close_lowers_the_threads_and_drops_the_timing() -> None:
    loop = Loop()
    for _ in range(4):
        loop.rollout()
    assert loop.threads.raised
    loop.threads.interrupted()
    assert not loop.threads.raised and loop.torch.threads == 1 and loop.pauses == 1
    assert len(loop.threads.timings.high) == 0  # the interrupted update was not timed


@pytest.fixture
def fake_torch(monkeypatch):
    return fake_torch_on(monkeypatch, cpus=2)


def test_auto_manages_the_update_where_it_lowered_and_says_so(fake_torch, monkeypatch):
    monkeypatch.setattr(torch_threads, "openmp_pause", lambda torch_dir: lambda: 0)
    threads = TorchThreads("auto", local_sims=2, away=lambda: None)
    with pytest.warns(TorchThreadsNotice, match=r"to 1 \(was 2\).*gives them back \(2\) for your learner's update"):
        threads.apply()
    assert threads.update is not None and (threads.update.low, threads.update.high) == (1, 2)


def test_no_update_threads_without_an_openmp_pause_or_a_way_to_tell_the_sims(fake_torch, monkeypatch):
    monkeypatch.setattr(torch_threads, "openmp_pause", lambda torch_dir: None)
    threads = TorchThreads("auto", local_sims=2, away=lambda: None)
    with pytest.warns(TorchThreadsNotice) as caught:
        threads.apply()
    assert threads.update is None and "gives them back" not in str(caught[0].message)
    torch_threads._Applied.done = False
    monkeypatch.setattr(torch_threads, "openmp_pause", lambda torch_dir: lambda: 0)
    quiet = TorchThreads("auto", local_sims=2)  # no away: e.g. the process floor
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        quiet.apply()
    assert quiet.update is None
    quiet.step_starts(), quiet.step_returns(), quiet.interrupted()  # nothing to do, no error


def test_the_openmp_pause_is_found_in_this_process_when_torch_is_loaded() -> None:
    pytest.importorskip("torch")
    import torch

    torch.ones(4).add_(1)  # torch's OpenMP runtime is loaded by now
    pause = update_threads.openmp_pause(os.path.dirname(torch.__file__))
    if pause is None:
        pytest.skip("this torch's OpenMP runtime offers no omp_pause_resource_all")
    assert pause() == 0


def test_the_sims_told_are_those_with_no_request_in_flight() -> None:
    from gymnasium import spaces

    from remoteenv.agent.connection.shared_lane_client import SharedLanes
    from remoteenv.wire.shared_memory.doorbell import AGENT_AWAY, Doorbell

    lanes = SharedLanes(spaces.Box(-1, 1, (3,)))
    headers = [np.zeros(16, dtype="<i8") for _ in range(3)]
    lanes._bells = {p: Doorbell(header, silent=True) for p, header in enumerate(headers)}
    lanes._pending = {2: 7}  # sim 2 still owes the reply to request 7 (send/recv)
    lanes.away()
    assert [int(header[AGENT_AWAY]) for header in headers] == [1, 1, 0]
    lanes.close()
