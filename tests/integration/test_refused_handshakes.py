"""A client the sim's gate refused gets in once a place is free.

The gate refuses a handshake while ``MAX_PEERS`` admitted connections are
open, and libzmq ends a refused connection for good, dropping what was queued
on it. The agent's ZeroMQ connection and the checker's probe connect again
after a pause and resend. Here a real gate (``open_router``) in this process
is full, one more client asks, a place frees up 0.3 s later, and the client's
request must be answered (without the retry it waits out its whole timeout).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zmq

from remoteenv.agent.connection.zmq_connection import ZmqConnection
from remoteenv.agent.errors import RemoteEnvTimeout
from remoteenv.compliance.probe import Probe, Target
from remoteenv.sim.transport.limits import MAX_PEERS
from remoteenv.sim.transport.router import open_router
from remoteenv.wire import protocol

FREE_AFTER_S = 0.3


class FullServer:
    """A gated ROUTER holding ``MAX_PEERS`` admitted clients, answering every request ``ok``."""

    def __init__(self, tmp_path: Path) -> None:
        self.ctx = zmq.Context()
        self.sock, self.gate = open_router(self.ctx, f"ipc://{tmp_path}/gate.sock")
        self.endpoint = self.sock.getsockopt(zmq.LAST_ENDPOINT).decode()
        self.client_ctx = zmq.Context()
        self.fillers = []
        for i in range(MAX_PEERS):
            filler = self.client_ctx.socket(zmq.DEALER)
            filler.setsockopt(zmq.LINGER, 0)
            filler.connect(self.endpoint)
            filler.send(protocol.pack({"seq": 1, "cmd": "filler", "n": i}))
            self.fillers.append(filler)
        for _ in range(MAX_PEERS):  # each filler's frame arrived: all are admitted
            assert self.sock.poll(10_000), "a filler was not admitted"
            self.sock.recv_multipart()
        self.answered: list[dict[str, Any]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            if self.sock.poll(20):
                routing_id, frame = self.sock.recv_multipart()
                request = protocol.decode_request(frame)
                self.answered.append(request)
                self.sock.send_multipart([routing_id, protocol.pack({"seq": request["seq"], "ok": True})])

    def free_a_place_later(self) -> threading.Timer:
        timer = threading.Timer(FREE_AFTER_S, self.fillers[0].close, kwargs={"linger": 0})
        timer.start()
        return timer

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        for filler in self.fillers:
            filler.close(linger=0)
        self.client_ctx.term()
        self.gate.stop()
        self.sock.close(linger=0)
        self.ctx.term()


@pytest.fixture
def full_server(tmp_path: Path) -> Iterator[FullServer]:
    server = FullServer(tmp_path)
    try:
        yield server
    finally:
        server.close()


def test_the_agent_connection_refused_by_a_full_sim_gets_in_when_a_place_frees(full_server):
    conn = ZmqConnection(full_server.endpoint, timeout=10.0)
    timer = full_server.free_a_place_later()
    try:
        started = time.monotonic()
        reply = conn.request("handshake", protocol=protocol.PROTOCOL_VERSION)
        waited = time.monotonic() - started
    finally:
        timer.join()
        conn.close()
    assert reply["ok"] is True
    assert full_server.gate.refused >= 1, "the gate never refused: the test did not test the retry"
    assert [r["cmd"] for r in full_server.answered] == ["handshake"]  # resent once it got in, not twice
    assert waited >= FREE_AFTER_S * 0.9  # it could only get in after the place freed


def test_a_refusal_names_the_full_sim_when_no_place_frees(full_server):
    conn = ZmqConnection(full_server.endpoint, timeout=1.0)
    try:
        with pytest.raises(RemoteEnvTimeout, match="refused this connection's ZeroMQ handshake"):
            conn.request("handshake", protocol=protocol.PROTOCOL_VERSION)
    finally:
        conn.close()
    assert full_server.answered == []


def test_a_request_sent_after_the_refusal_does_not_block_and_both_are_answered(full_server):
    # libzmq has no connection to queue a frame on once it ended the refused one:
    # a plain send would block for good. The second request goes with the next try.
    conn = ZmqConnection(full_server.endpoint, timeout=10.0)
    try:
        first = conn.send("handshake", protocol=protocol.PROTOCOL_VERSION)
        deadline = time.monotonic() + 10
        while conn.socket.getsockopt(zmq.EVENTS) & zmq.POLLOUT and time.monotonic() < deadline:
            time.sleep(0.01)  # until libzmq has ended the refused connection: nothing to queue on
        assert full_server.gate.refused >= 1 and not conn.socket.getsockopt(zmq.EVENTS) & zmq.POLLOUT
        sent: list[int] = []
        sender = threading.Thread(target=lambda: sent.append(conn.send("ping")), daemon=True)
        sender.start()
        sender.join(5)
        assert sent, "a send after the refusal blocked"
        timer = full_server.free_a_place_later()
        try:
            assert conn.receive(first)["ok"] is True
            assert conn.receive(sent[0])["ok"] is True
        finally:
            timer.join()
    finally:
        conn.close()
    assert [r["cmd"] for r in full_server.answered] == ["handshake", "ping"]


def test_the_checkers_probe_refused_by_a_full_server_gets_in_when_a_place_frees(full_server):
    timer = full_server.free_a_place_later()
    try:
        with Probe(Target(endpoint=full_server.endpoint, timeout=10.0)) as probe:
            reply = probe.call("handshake", protocol=protocol.PROTOCOL_VERSION)
            refusals = probe.watch.refusals
    finally:
        timer.join()
    assert reply["ok"] is True
    assert refusals >= 1 and full_server.gate.refused >= 1
    assert [r["cmd"] for r in full_server.answered] == ["handshake"]
