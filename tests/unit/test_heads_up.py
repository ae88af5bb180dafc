"""The fast lane's heads-up, each end alone: the agent's pipe asks for one when
it blocks for a region reply and waits hot from it (a stand-in sim on a
socketpair, in a thread); the sim's lane sends one only to an agent that
sleeps and asked, and not after a long tail."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
from fakes import heads_up_once_asked, in_thread, until
from gymnasium import spaces

from remoteenv.agent.connection.pipe_connection import PipeConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.sim.transport.shared_lane_server import HEADS_UP_TAIL_S, SharedLane
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory import hot_wait
from remoteenv.wire.shared_memory.doorbell import AGENT_HEADS_UP, AGENT_WATCHING, Doorbell
from remoteenv.wire.shared_memory.hot_wait import usable_cpus

needs_two_cpus = pytest.mark.skipif(usable_cpus() < 2, reason="no hot waits (nor heads-ups) on one CPU")


def _send(sock: socket.socket, message: dict) -> None:
    sock.sendall(protocol.stream_frame(protocol.pack(message)))


@needs_two_cpus
def test_a_blocked_agent_asks_and_takes_the_region_reply_after_the_heads_up(lane, monkeypatch):
    conn, agent_bell, sim_end, sim_bell = lane
    # The woken agent waits hot until the reply, however the scheduler runs the two threads
    # (beside busy CPUs a 1 ms window, or a stall, could end it first: then a frame is due).
    conn._soon.window_s = 30.0
    monkeypatch.setattr(hot_wait, "STALL_S", 30.0)
    seq = conn.post(agent_bell, 1, False)

    wake_frames: list[bool] = []

    def sim() -> None:
        heads_up_once_asked(sim_bell, sim_end, seq)
        until(lambda: not sim_bell.agent_wants_heads_up())  # woken: watching again
        time.sleep(0.0003)  # the rest of the tick
        wake_frames.append(sim_bell.reply(seq, 0))

    thread = in_thread(sim)
    assert conn.receive(seq) == {"seq": seq, "ok": True, "region": True}
    thread.join(5)
    assert wake_frames == [False]  # the woken agent watched: the reply needed no frame
    assert conn.heads_ups == 1 and agent_bell.word(AGENT_HEADS_UP) == 0


@needs_two_cpus
def test_an_error_after_the_heads_up_is_raised(lane):
    conn, agent_bell, sim_end, sim_bell = lane
    seq = conn.post(agent_bell, 1, False)

    def sim() -> None:
        heads_up_once_asked(sim_bell, sim_end, seq)
        time.sleep(0.0003)
        _send(sim_end, protocol.error_reply(seq, "scene", "the hook raised"))

    thread = in_thread(sim)
    with pytest.raises(RemoteEnvError, match="the hook raised") as info:
        conn.receive(seq)
    thread.join(5)
    assert info.value.kind == "scene" and conn.heads_ups == 1


@needs_two_cpus
def test_a_heads_up_for_another_request_answers_nothing(lane):
    conn, agent_bell, sim_end, sim_bell = lane
    seq = conn.post(agent_bell, 1, False)

    def sim() -> None:
        heads_up_once_asked(sim_bell, sim_end, seq - 1)  # not the awaited request's
        time.sleep(0.002)
        until(sim_bell.agent_wants_heads_up)  # it dropped it and blocked again
        if sim_bell.reply(seq, 0):
            _send(sim_end, {"seq": seq, "ok": True, "region": True})

    thread = in_thread(sim)
    assert conn.receive(seq) == {"seq": seq, "ok": True, "region": True}
    thread.join(5)
    assert conn.heads_ups == 0


def test_an_agent_told_not_to_wait_hot_blocks_without_asking(lane, monkeypatch):
    monkeypatch.setenv("REMOTEENV_NO_SPIN", "1")
    _, agent_bell, _, sim_bell = lane
    own_end = socket.socketpair()
    conn = PipeConnection(own_end[0], timeout=10.0)  # made with the variable set
    try:
        seq = conn.post(agent_bell, 1, False)
        seen: list[int] = []

        def sim() -> None:
            until(lambda: agent_bell.word(AGENT_WATCHING) == 0)  # it blocks
            seen.append(agent_bell.word(AGENT_HEADS_UP))
            if sim_bell.reply(seq, 0):
                own_end[1].sendall(protocol.stream_frame(protocol.pack({"seq": seq, "ok": True, "region": True})))

        thread = in_thread(sim)
        assert conn.receive(seq)["region"] is True
        thread.join(5)
        assert seen == [0] and conn.heads_ups == 0
    finally:
        conn.close()
        own_end[1].close()


class _Pipe:
    """Stands in for the sim's pipe channel: keeps what is sent."""

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def send(self, reply_to, payload: bytes) -> None:
        self.sent.append(payload)


def _sim_lane() -> tuple[SharedLane, Doorbell, _Pipe]:
    lane = SharedLane(spaces.Box(-1, 1, (2,), np.float32), spaces.Box(-1, 1, (3,), np.float64), 2)
    header = np.zeros(16, dtype="<i8")
    lane.doorbell = Doorbell(header, silent=True)
    pipe = _Pipe()
    lane._channel = pipe  # type: ignore[assignment]  # set by take() for a request from the pipe
    return lane, Doorbell(header, silent=True), pipe


def test_the_sim_sends_a_heads_up_only_to_an_agent_that_sleeps_and_asked():
    lane, agent, pipe = _sim_lane()
    agent.post(1, 1, False)
    lane.physics_done(1)  # awake
    agent.agent_sleeps(1)
    lane.physics_done(1)  # asleep, did not ask
    assert pipe.sent == []
    agent.agent_wakes()
    agent.agent_sleeps(1, heads_up=True)
    lane.physics_done(1)
    assert pipe.sent == [protocol.reply_soon(1)]


def test_a_sim_whose_tick_runs_long_after_its_physics_stops_and_resumes_its_heads_ups():
    lane, agent, pipe = _sim_lane()
    agent.post(1, 1, False)
    agent.agent_sleeps(1, heads_up=True)
    lane.physics_done(1)
    time.sleep(HEADS_UP_TAIL_S * 1.5)
    lane.answer(1, None)  # type: ignore[arg-type]  # no region yet: answered elsewhere, its tail measured
    lane.physics_done(2)
    assert pipe.sent == [protocol.reply_soon(1)]  # not for 2: the last tick ran long after its physics
    lane.answer(2, None)  # type: ignore[arg-type]  # a short one
    lane.physics_done(3)
    assert pipe.sent == [protocol.reply_soon(1), protocol.reply_soon(3)]


def test_a_late_heads_up_read_while_watching_leaves_the_region_reply_to_be_found(lane):
    """A heads-up the sim sent just as the agent's blocking read timed out
    arrives while the agent watches the region again, and is read by a
    non-blocking look. It answers nothing and must not end the watch: the
    sim, finding the agent watching, answers in the region with no frame."""
    conn, agent_bell, sim_end, sim_bell = lane
    seq = conn.post(agent_bell, 1, False)
    sim_end.sendall(protocol.stream_frame(protocol.reply_soon(seq)))
    deadline = time.monotonic() + 5
    while conn.pipe.recv(64, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b"" and time.monotonic() < deadline:
        time.sleep(0.001)
    assert conn.try_receive(seq) is None  # the heads-up was read and dropped
    assert sim_bell.reply(seq, 0) is False  # the agent watches: no wake-up frame
    assert conn.try_receive(seq) == {"seq": seq, "ok": True, "region": True}
