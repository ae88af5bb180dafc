"""The sim's ZeroMQ intake, in-process: at most MAX_PEERS connections are
admitted, the frames of the connections driving a world come first, other
connections' frames wait in a bounded backlog served within a byte budget
per pass (a frame that finds the backlog full is dropped and answered
``busy``), and their expensive requests get one turn per pass.

The channel's policy is tested over a fake ROUTER (frames queued by the
test: exact passes); the gate over real DEALER sockets in this process.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Iterator
from typing import Any

import pytest
import zmq

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.sim.transport import channels, limits
from remoteenv.sim.transport.channels import ZmqChannel
from remoteenv.wire import protocol

OWNER, OTHER, THIRD = b"\x00owner", b"\x00other", b"\x00third"


class FakeFrame(bytes):
    """A received body part: a buffer with ``more`` (False: the last part) and
    ``get(zmq.SRCFD)``, its connection's descriptor (:data:`FDS` by routing id)."""

    more = False
    fd = 0

    def get(self, option: int) -> int:
        assert option == zmq.SRCFD
        return self.fd


#: The connection descriptor each routing id's frames come on.
FDS: dict[bytes, int] = {OWNER: 11, OTHER: 12, THIRD: 13}


class FakeRouter:
    """Stands for the bound ROUTER: ``queued`` (routing id, body) pairs arrive in order."""

    def __init__(self, queued: list[tuple[bytes, bytes]] = ()) -> None:
        self.queued = collections.deque(queued)
        self.sent: list[tuple[bytes, dict[str, Any]]] = []
        self._body: bytes | None = None
        self._routing_id = b""

    def getsockopt(self, option: int) -> int:
        if option == zmq.EVENTS:
            return zmq.POLLIN if self.queued else 0
        return 0  # FD, RCVMORE

    def recv(self, flags: int = 0, copy: bool = True) -> Any:
        if self._body is None:
            routing_id, self._body = self.queued.popleft()
            self._routing_id = routing_id
            return routing_id
        body, self._body = self._body, None
        frame = FakeFrame(body)
        frame.fd = FDS.get(self._routing_id, 0)
        return frame

    def send_multipart(self, parts: list[bytes]) -> None:
        self.sent.append((parts[0], protocol.unpack(parts[1])))


def request(seq: int, cmd: str, **fields: Any) -> bytes:
    return protocol.pack({"seq": seq, "cmd": cmd, **fields})


def padded(seq: int, kib: int) -> bytes:
    return request(seq, "no-such-command", pad=bytes(kib << 10))


def ids(frames: list[tuple[bytes, Any]]) -> list[tuple[bytes, int]]:
    return [(rid, protocol.unpack(bytes(f))["seq"]) for rid, f in frames]


# ---------------------------------------------------------------- the channel's policy


def test_a_peer_whose_connection_ended_is_reported_gone_once_by_routing_id():
    # Issue 35, item 4: the driver rule releases a world when its driver's
    # connection ends (the socket monitor's DISCONNECTED, by descriptor).
    router = FakeRouter([(OWNER, request(1, "step")), (OTHER, request(2, "render"))])
    ended: list[int] = []
    gone: list[bytes] = []
    channel = ZmqChannel(router, owners=lambda: {OWNER}, disconnected=lambda: ended[:], gone=gone.append)
    channel.receive_nowait()
    ended.append(FDS[OWNER])
    channel.receive_nowait()
    ended.clear()
    channel.receive_nowait()
    assert gone == [OWNER]


def test_the_drivers_frames_come_first_then_the_others_in_arrival_order():
    router = FakeRouter([(OTHER, request(1, "render")), (THIRD, request(2, "render")), (OWNER, request(3, "step"))])
    channel = ZmqChannel(router, owners=lambda: {OWNER})
    assert ids(channel.receive_nowait()) == [(OWNER, 3), (OTHER, 1), (THIRD, 2)]
    assert not channel.more


def test_the_others_share_a_byte_budget_per_pass_and_the_first_always_goes():
    router = FakeRouter([(OTHER, padded(i, 600)) for i in range(3)] + [(THIRD, padded(9, 2048))])
    channel = ZmqChannel(router, owners=lambda: {OWNER})
    passes = []
    while True:
        passes.append([seq for _, seq in ids(channel.receive_nowait())])
        if not channel.more:
            break
    # 600 KiB + 600 KiB exceed the 1 MiB budget: one a pass; the 2 MiB frame alone.
    assert limits.OTHERS_BYTES_PER_PASS == 1 << 20
    assert passes == [[0], [1], [2], [9]]
    assert router.sent == []


def test_a_frame_that_finds_the_backlog_full_is_dropped_and_answered_busy(monkeypatch):
    monkeypatch.setattr(channels, "BACKLOG_BYTES", 2 << 20)
    router = FakeRouter([(OTHER, padded(i, 900)) for i in range(5)] + [(OWNER, request(7, "step"))])
    channel = ZmqChannel(router, owners=lambda: {OWNER})
    assert ids(channel.receive_nowait()) == [(OWNER, 7), (OTHER, 0)]
    assert ids(channel.receive_nowait()) == [(OTHER, 1)]
    assert not channel.more and channel.dropped == 3  # 3 x 900 KiB did not fit beside the first two
    assert [(rid, r["seq"], r["ok"], r["error"]["kind"]) for rid, r in router.sent] == [
        (OTHER, 2, False, "state"),
        (OTHER, 3, False, "state"),
        (OTHER, 4, False, "state"),
    ]
    assert "busy" in router.sent[0][1]["error"]["message"]


def test_a_pass_takes_at_most_frames_per_drain_out_of_libzmq():
    router = FakeRouter([(OWNER, request(i, "step")) for i in range(limits.FRAMES_PER_DRAIN + 5)])
    channel = ZmqChannel(router, owners=lambda: {OWNER})
    assert len(channel.receive_nowait()) == limits.FRAMES_PER_DRAIN and channel.more
    assert len(channel.receive_nowait()) == 5 and not channel.more


def test_deferred_frames_go_back_in_front_in_their_order():
    router = FakeRouter([(OTHER, request(i, "render")) for i in range(3)])
    channel = ZmqChannel(router, owners=frozenset)
    first = channel.receive_nowait()
    channel.defer(first)
    assert channel.more
    assert [seq for _, seq in ids(channel.receive_nowait())] == [0, 1, 2]


def test_peek_seq_reads_the_seq_from_the_first_bytes_only():
    assert protocol.peek_seq(request(12345, "step", action=1)) == 12345
    assert protocol.peek_seq(protocol.pack({"pad": bytes(1000), "seq": 5})) == -1  # beyond the first bytes
    assert protocol.peek_seq(b"\xc1garbage") == -1
    assert protocol.peek_seq(protocol.pack([1, 2])) == -1


# ---------------------------------------------------------------- the server's budgets


@pytest.fixture
def server(tmp_path) -> Iterator[RemoteControlledAgent]:
    srv = RemoteControlledAgent(
        [CartPoleEnv(render_mode="rgb_array", width=32, height=24)], f"ipc://{tmp_path}/sim.sock"
    )
    yield srv
    srv.shutdown()


def one_pass(server: RemoteControlledAgent, router: FakeRouter) -> list[tuple[bytes, int]]:
    """One pass of the server's loop over the fake router: the (peer, seq) answered."""
    server._expensive_left = limits.EXPENSIVE_PER_PASS
    before = len(router.sent)
    server._answer(server.router, server.router.receive_nowait())
    return [(rid, r["seq"]) for rid, r in router.sent[before:]]


def test_expensive_requests_of_other_connections_get_one_turn_per_pass(server):
    router = FakeRouter()
    server.router = ZmqChannel(router, owners=lambda: server.drivers.routing_ids)
    server.handle({"seq": 1, "cmd": "reset", "seed": 0}, server.router, OWNER)  # OWNER drives world 0
    router.queued.extend([(OTHER, request(10 + i, "render")) for i in range(3)])
    router.queued.extend([(OWNER, request(2, "step", action=1)), (OWNER, request(3, "render"))])
    router.queued.append((OTHER, request(20, "get_attr", name="continuous")))
    assert one_pass(server, router) == [(OWNER, 2), (OWNER, 3), (OTHER, 10)]  # the owner's own render is not counted
    assert one_pass(server, router) == [(OTHER, 11)]
    assert one_pass(server, router) == [(OTHER, 12)]
    assert one_pass(server, router) == [(OTHER, 20)]
    assert not server.router.more
    assert all(r["ok"] for _, r in router.sent)


def test_cheap_requests_of_other_connections_are_not_held_back_by_the_render_budget(server):
    router = FakeRouter([(OTHER, request(1, "render")), (THIRD, request(2, "handshake", protocol=1))])
    server.router = ZmqChannel(router, owners=frozenset)
    # The render spends the pass's share of expensive requests; a cheap one still goes.
    assert one_pass(server, router) == [(OTHER, 1), (THIRD, 2)]


# ---------------------------------------------------------------- the gate (real sockets)

# Waiting for frames to cross a socket: generous, and never the thing under test.
WAIT_S = 30.0


def _wait_for(condition, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"waited {WAIT_S} s for {what}"
        time.sleep(0.01)


def test_the_gate_admits_at_most_max_peers_and_admits_again_when_one_leaves(server):
    # A refused DEALER does not retry (libzmq ends a connection refused by ZAP);
    # a client that wants in again connects anew, as the agent does after a timeout.
    # The clients live in the process's shared context, as the agent's connections
    # do, which is never terminated: terminating a context of its own after these
    # refusals hung once in CI (2026-11-29), every socket closed with linger 0 (a
    # rare hang in libzmq's ctx_t::terminate, libzmq issue #2586). No send blocks:
    # a client refused before its send has no connection to queue on, and a
    # blocking send would then wait for good (twice beside two CPU hogs).
    ctx = zmq.Context.instance()
    socks = []
    try:
        for i in range(limits.MAX_PEERS + 3):
            sock = ctx.socket(zmq.DEALER)
            sock.setsockopt(zmq.LINGER, 0)
            sock.connect(server.endpoint)
            socks.append(sock)
            try:
                sock.send(request(i, "handshake", protocol=1), zmq.NOBLOCK)
            except zmq.Again:
                # Refused already (a busy machine can run connect, greeting and
                # ZAP refusal between two lines here): libzmq has dropped the
                # connection, so a blocking send would wait for good.
                assert i >= limits.MAX_PEERS, f"admitted client {i} had no connection to send on"
        got: list[tuple[bytes, Any]] = []

        def seen(count: int):
            def enough() -> bool:
                got.extend(server.router.receive_nowait())
                return len(got) >= count

            return enough

        _wait_for(seen(limits.MAX_PEERS), f"{limits.MAX_PEERS} admitted peers' frames")
        _wait_for(lambda: server._gate.refused >= 3, "three refused handshakes")
        got.extend(server.router.receive_nowait())
        assert len({rid for rid, _ in got}) == limits.MAX_PEERS  # the others never got a connection
        admitted = {seq for _, seq in ids(got)}
        socks[min(admitted)].close(linger=0)  # one leaves: a newcomer gets its place
        # once the gate has seen it leave (the monitor's event and the newcomer's
        # handshake are separate events; a newcomer ahead of it is refused, and
        # a refused DEALER does not retry)
        _wait_for(
            lambda: server._gate.count.admitted(time.monotonic()) < limits.MAX_PEERS, "the gate to see a peer leave"
        )
        newcomer = ctx.socket(zmq.DEALER)
        newcomer.setsockopt(zmq.LINGER, 0)
        socks.append(newcomer)
        newcomer.connect(server.endpoint)
        newcomer.send(request(99, "handshake", protocol=1), zmq.NOBLOCK)  # admitted: its connection is there
        _wait_for(seen(limits.MAX_PEERS + 1), "the newcomer's frame")
        assert ids(got)[-1][1] == 99
    finally:
        for sock in socks:
            sock.close(linger=0)


def test_the_peer_count_follows_the_monitor_events_libzmq_sends():
    from remoteenv.sim.transport.peer_gate import PeerCount

    E = zmq
    count = PeerCount(handshake_s=2.0)
    # An idle or garbage connection: accepted, handshake failed, disconnected.
    for failed in (E.EVENT_HANDSHAKE_FAILED_NO_DETAIL, E.EVENT_HANDSHAKE_FAILED_PROTOCOL):
        count.event(E.EVENT_ACCEPTED, 15)
        count.event(failed, 0)
        count.event(E.EVENT_DISCONNECTED, 15)
        assert count.admitted(0.0) == 0
    # Two admitted, one still in its handshake (not counted: an idle storm must not lock clients out).
    count.event(E.EVENT_ACCEPTED, 16)
    count.admit(0.0)
    assert count.admitted(0.0) == 1  # admitted by the gate, handshake not done yet
    count.event(E.EVENT_HANDSHAKE_SUCCEEDED, 0)
    count.event(E.EVENT_ACCEPTED, 17)
    count.admit(0.1)
    count.event(E.EVENT_HANDSHAKE_SUCCEEDED, 0)
    count.event(E.EVENT_ACCEPTED, 18)
    assert count.admitted(0.2) == 2
    count.event(E.EVENT_DISCONNECTED, 16)
    assert count.admitted(0.3) == 1
    # An admission whose handshake never completes stops counting after the handshake interval.
    count.event(E.EVENT_ACCEPTED, 19)
    count.admit(1.0)
    assert count.admitted(1.5) == 2 and count.admitted(3.5) == 1
    # Whatever went astray, no connection left means nobody admitted.
    count.event(E.EVENT_HANDSHAKE_SUCCEEDED, 0)  # e.g. one whose disconnect came first
    for fd in (17, 18, 19):
        count.event(E.EVENT_DISCONNECTED, fd)
    assert count.admitted(4.0) == 0
