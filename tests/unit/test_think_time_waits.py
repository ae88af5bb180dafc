"""The agent's think time on the fast lane's doorbell (``AGENT_THINK_US``), and the
sim's waits: no hot wait for the next request after a request whose agent said
it thinks longer than the limit; a hot wait as before after a short think."""

from __future__ import annotations

import socket
from typing import Any

import numpy as np
from fakes import IdleRouter

from remoteenv.sim.serving.waits import ServingWaits
from remoteenv.sim.transport.channels import PipeChannel
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory import hot_wait
from remoteenv.wire.shared_memory.doorbell import AGENT_THINK_US, MAX_THINK_US, Doorbell


def test_the_agent_writes_its_think_time_in_microseconds_and_the_sim_reads_it_clamped() -> None:
    header = np.zeros(16, dtype="<i8")
    agent, sim = Doorbell(header, silent=True), Doorbell(header, silent=True)
    agent.post(1, 3, False, think_s=750e-6)
    assert header[AGENT_THINK_US] == 750
    assert sim.agent_think_s() == 750e-6
    agent.post(2, 3, False)  # not told: 0
    assert sim.agent_think_s() == 0.0
    header[AGENT_THINK_US] = -5  # a hint from the peer, read as found: clamped, never an error
    assert sim.agent_think_s() == 0.0
    header[AGENT_THINK_US] = 1 << 62
    assert sim.agent_think_s() == MAX_THINK_US * 1e-6
    agent.post(3, 3, False, think_s=1e12)
    assert header[AGENT_THINK_US] == MAX_THINK_US


class Lane:
    """A pipe's fast lane with nothing posted, whose last request told
    ``agent_think_s``; the agent says it is away from its ``away_from``-th look on."""

    def __init__(self, agent_think_s: float, away_from: int | None = None) -> None:
        self.agent_think_s = agent_think_s
        self.away_from = away_from
        self.looks = 0

    def posted(self) -> int:
        return 0

    def settle(self) -> int:
        return 0

    def agent_away(self) -> bool:
        self.looks += 1
        return self.away_from is not None and self.looks >= self.away_from


def _waits(pipe: PipeChannel, quiet: socket.socket, answer: Any) -> ServingWaits:
    """The sim's waits over ``pipe`` and a router on which nothing comes: hot for up to
    50 ms, a think longer than 200 us announced, frames to ``answer``."""
    waits = ServingWaits(
        IdleRouter(quiet),  # type: ignore[arg-type]
        pipe,
        hot_window_s=0.05,
        think_limit_s=200e-6,
        spin_s=0.0,
        answer=answer,
        send=lambda outgoing: None,
        pipe_closed=lambda: None,
    )
    waits.hot.window_s = 0.05  # whatever this machine's CPUs or REMOTEENV_NO_SPIN say
    return waits


def _one_pass(agent_think_s: float, away_from: int | None = None) -> tuple[list[Any], int]:
    """One lock-step pass over a pipe holding one request: what was answered, and
    how many times the pass waited hot on the pipe."""
    agent, sim = socket.socketpair()
    quiet_a, quiet_b = socket.socketpair()
    pipe = PipeChannel(sim.detach())
    answered: list[Any] = []
    try:
        pipe.lane = Lane(agent_think_s, away_from)
        spins = []
        receive_spinning = pipe.receive_spinning

        def spy(hot: Any) -> list[tuple[Any, Any]]:
            spins.append(1)
            return receive_spinning(hot)

        pipe.receive_spinning = spy  # type: ignore[method-assign]
        waits = _waits(pipe, quiet_a, answer=lambda channel, frames: answered.extend(frames))
        hot_wait._Neighbours.cool_until = 0.0  # nor an earlier spin's stall beside a busy neighbour
        agent.sendall(protocol.stream_frame(protocol.pack({"seq": 1, "cmd": "ping"})))
        waits.for_requests()
        return answered, len(spins)
    finally:
        pipe.close()
        for s in (agent, quiet_a, quiet_b):
            s.close()


def test_after_a_long_think_the_sim_does_not_wait_hot_and_still_serves_the_request() -> None:
    answered, spins = _one_pass(agent_think_s=1e-3)
    assert spins == 0
    assert [protocol.peek_seq(frame) for _, frame in answered] == [1]


def test_after_a_short_or_untold_think_the_sim_waits_hot_as_before() -> None:
    for think in (50e-6, 0.0):
        answered, spins = _one_pass(agent_think_s=think)
        assert spins == 1
        assert [protocol.peek_seq(frame) for _, frame in answered] == [1]


def test_an_agent_away_before_the_wait_means_no_hot_wait() -> None:
    answered, spins = _one_pass(agent_think_s=50e-6, away_from=1)
    assert spins == 0
    assert [protocol.peek_seq(frame) for _, frame in answered] == [1]


def test_an_agent_gone_away_during_a_hot_wait_ends_it_at_the_next_look(monkeypatch) -> None:
    """The spin on a quiet pipe stops at the look that finds ``AGENT_AWAY``, long
    before its window (10 s) would end it. (A busy machine may deschedule the
    spin between two looks; that is not a stall here, or the wait would end
    for that reason instead.)"""
    sim_end, agent_end = socket.socketpair()
    pipe = PipeChannel(sim_end.detach())
    try:
        lane = Lane(0.0, away_from=3)
        pipe.lane = lane
        hot = hot_wait.HotWait(10.0)
        hot.window_s = 10.0
        monkeypatch.setattr(hot_wait._Neighbours, "cool_until", 0.0)
        monkeypatch.setattr(hot_wait, "STALL_S", float("inf"))
        assert hot.worth_it()
        assert pipe.receive_spinning(hot) == []
        assert lane.looks == 3
    finally:
        pipe.close()
        agent_end.close()


def test_a_wait_through_an_announced_think_is_not_held_against_the_next_request(monkeypatch) -> None:
    """The sim blocked through the agent's update (``AGENT_AWAY``): the request after it
    is waited for hot, as the ones before the update were, not as after a slow agent."""
    agent, sim = socket.socketpair()
    quiet_a, quiet_b = socket.socketpair()
    pipe = PipeChannel(sim.detach())
    try:
        lane = Lane(0.0, away_from=1)
        pipe.lane = lane
        waits = _waits(pipe, quiet_a, answer=lambda channel, frames: None)
        monkeypatch.setattr(hot_wait._Neighbours, "cool_until", 0.0)
        waits.hot.waited(1e-4)  # the agent's steps came quickly so far
        waits.hot.since -= 10.0  # then it went away for 10 s (its update)
        agent.sendall(protocol.stream_frame(protocol.pack({"seq": 1, "cmd": "ping"})))
        waits.for_requests()  # blocked: the agent said it was away
        lane.away_from = None  # the next request came with its step
        assert waits.hot.worth_it()
    finally:
        pipe.close()
        for s in (agent, quiet_a, quiet_b):
            s.close()
