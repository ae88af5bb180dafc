"""Where a sim process's requests come from: its ZeroMQ ROUTER and its local pipe.

Runs in the sim process. Both channels carry the frames of
:mod:`remoteenv.wire.protocol`; the server's loop treats them alike through
the :class:`Channel` interface: ``receive_nowait`` (the frames that have
arrived, each with whom to answer) and ``send``.
"""

from __future__ import annotations

import collections
import socket
from collections.abc import Callable, Collection
from typing import Any, Protocol

import zmq

from remoteenv.sim.transport.limits import BACKLOG_BYTES, FRAMES_PER_DRAIN, MAX_PEERS, OTHERS_BYTES_PER_PASS
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory.hot_wait import HotWait
from remoteenv.wire.wire_errors import PROTOCOL, STATE

#: A hot wait on the pipe with a region reads the pipe once every this many looks at the region.
PIPE_LOOK_EVERY = 4
#: Routing ids whose connection is noted at most (beyond: drivers' only).
_MAX_PEERS_NOTED = 4 * MAX_PEERS


class Channel(Protocol):
    """Where requests come from and their replies go."""

    #: True once the channel can carry nothing more (the pipe's end of file).
    closed: bool
    #: What to register in a ``zmq.Poller``.
    pollable: Any
    #: A file descriptor that becomes readable when requests may be waiting.
    fd: int
    #: True when the last :meth:`receive_nowait` left requests waiting (it takes a bounded number).
    more: bool

    def receive_nowait(self) -> list[tuple[Any, Any]]:
        """The request frames that have arrived (``bytes`` or another buffer; a
        request the channel read other than as a frame comes as its decoded
        map), each with whom to answer (never blocks)."""
        ...

    def send(self, reply_to: Any, payload: bytes) -> None:
        """Send one encoded reply to ``reply_to`` (a value ``receive_nowait`` gave)."""
        ...


#: A reply to send later: the channel (None for a request handed to the server
#: directly, whose late reply has nowhere to go), whom to answer there, and the
#: reply map (with its ``seq``); produced by real-time stepping when a tick ends.
Outgoing = tuple["Channel | None", Any, dict[str, Any]]


class ZmqChannel:
    """The bound ROUTER socket; ``reply_to`` is the peer's routing id.

    :meth:`receive_nowait` takes at most :data:`~remoteenv.sim.transport.limits.FRAMES_PER_DRAIN`
    frames out of libzmq per call (zero-copy: a frame is a ``zmq.Frame``, read
    through the buffer protocol). Frames of the connections that drive a world
    (``owners()``, their routing ids) are served at once; other frames wait
    in a backlog of at most :data:`~remoteenv.sim.transport.limits.BACKLOG_BYTES`, from
    which each call serves :data:`~remoteenv.sim.transport.limits.OTHERS_BYTES_PER_PASS`
    (at least one frame), oldest first. A frame that finds the backlog full is
    dropped unread and answered with a ``state`` error (see :meth:`drop`).
    :attr:`more` says whether frames were left waiting.

    Peers that leave: each frame's connection (its descriptor in libzmq's
    I/O thread, ``SRCFD``) is noted by routing id, and a connection the
    socket monitor reports ended (``disconnected()``, descriptors, from the
    gate: :class:`~remoteenv.sim.transport.peer_gate.PeerGate`) is passed to
    ``gone`` with each routing id seen on it, at the start of the next call.

    Args:
        sock: the bound ROUTER.
        owners: the routing ids whose frames go first (read on every call).
        disconnected: the descriptors of connections that ended since the last call.
        gone: called with the routing id of a peer whose connection ended.
    """

    def __init__(
        self,
        sock: zmq.Socket,
        owners: Callable[[], Collection[bytes]] = frozenset,
        disconnected: Callable[[], list[int]] = list,
        gone: Callable[[bytes], None] = lambda routing_id: None,
    ) -> None:
        self.socket = sock
        self.closed = False
        #: What to register in a ``zmq.Poller``.
        self.pollable: Any = sock
        #: A file descriptor that becomes readable when requests may be waiting
        #: (edge-triggered: always drain with :meth:`receive_nowait`).
        self.fd: int = int(sock.getsockopt(zmq.FD))
        #: True when the last :meth:`receive_nowait` left frames waiting.
        self.more = False
        #: Frames dropped unread because the backlog was full.
        self.dropped = 0
        self._owners = owners
        self._disconnected = disconnected
        self._gone = gone
        #: routing id -> the descriptor of the connection its last frame came on.
        self._fd_of: dict[bytes, int] = {}
        self._backlog: collections.deque[tuple[bytes, Any]] = collections.deque()
        self._backlog_bytes = 0

    def receive_nowait(self) -> list[tuple[Any, Any]]:
        fd_of = self._fd_of
        for fd in self._disconnected():
            for routing_id in [r for r, f in fd_of.items() if f == fd]:
                del fd_of[routing_id]
                self._gone(routing_id)
        sock = self.socket
        owners = self._owners()
        if len(fd_of) > _MAX_PEERS_NOTED:  # notices lost under churn: only drivers need one
            self._fd_of = fd_of = {r: f for r, f in fd_of.items() if r in owners}
        backlog = self._backlog
        out: list[tuple[Any, Any]] = []
        taken = 0
        while taken < FRAMES_PER_DRAIN and sock.getsockopt(zmq.EVENTS) & zmq.POLLIN:  # type: ignore[arg-type,operator]
            taken += 1
            routing_id = sock.recv(zmq.NOBLOCK)
            frame = sock.recv(zmq.NOBLOCK, copy=False)
            if frame.more:  # not a DEALER-framed request: drop all of it
                while sock.getsockopt(zmq.RCVMORE):
                    sock.recv(zmq.NOBLOCK, copy=False)
                continue
            fd_of[routing_id] = _source_fd(frame)
            if routing_id in owners:
                out.append((routing_id, frame))
                continue
            size = len(frame)
            if backlog and self._backlog_bytes + size > BACKLOG_BYTES:
                self.drop(routing_id, frame)
                continue
            backlog.append((routing_id, frame))
            self._backlog_bytes += size
        budget, first = OTHERS_BYTES_PER_PASS, True
        while backlog and (first or len(backlog[0][1]) <= budget):
            routing_id, frame = backlog.popleft()
            size = len(frame)
            self._backlog_bytes -= size
            budget -= size
            first = False
            out.append((routing_id, frame))
        self.more = bool(backlog) or (taken == FRAMES_PER_DRAIN and bool(sock.getsockopt(zmq.EVENTS) & zmq.POLLIN))  # type: ignore[arg-type,operator]
        return out

    def budgeted(self, reply_to: Any) -> bool:
        """Whether requests from ``reply_to`` share the per-pass budgets (it drives no world)."""
        return reply_to not in self._owners()

    def defer(self, frames: list[tuple[Any, Any]]) -> None:
        """Put ``frames`` (from :meth:`receive_nowait`, in order) back at the front of the backlog."""
        for routing_id, frame in reversed(frames):
            self._backlog.appendleft((routing_id, frame))
            self._backlog_bytes += len(frame)
        self.more = bool(self._backlog)

    def drop(self, routing_id: bytes, frame: Any) -> None:
        """Drop ``frame`` unread and tell its sender (``seq`` read from its first bytes, else -1)."""
        self.dropped += 1
        reply = protocol.error_reply(
            protocol.peek_seq(frame),
            STATE,
            f"request dropped unread: this sim is busy ({BACKLOG_BYTES >> 20} MiB of requests from "
            "connections that drive no world are waiting); retry later",
        )
        self.socket.send_multipart([routing_id, protocol.pack(reply)])

    def send(self, reply_to: Any, payload: bytes) -> None:
        self.socket.send_multipart([reply_to, payload])


def _source_fd(frame: Any) -> int:
    """The descriptor of the connection ``frame`` came on (-1 where libzmq has
    none to say, e.g. inproc: such a peer is never reported gone)."""
    try:
        return int(frame.get(zmq.SRCFD))
    except zmq.ZMQError:
        return -1


class LaneWatch(Protocol):
    """The fast lane of a pipe's shared region (:class:`remoteenv.sim.transport.shared_lane_server.SharedLane`)."""

    #: The agent's think time before the last request taken from the region (seconds, 0: not told).
    agent_think_s: float

    def posted(self) -> int:
        """``seq`` of a request posted in the region and not yet served (0: none)."""
        ...

    def settle(self) -> int:
        """About to block: stop watching; a request posted meanwhile (0: none)."""
        ...

    def agent_away(self) -> bool:
        """Whether the agent said its caller began a long think after the last reply."""
        ...


class PipeChannel:
    """The inherited end of the launcher's socketpair; one peer, no routing id.

    ``closed`` becomes True at end of file (the agent closed its end or died).
    A frame above the frame limit is skipped and answered here with a
    ``protocol`` error (``seq`` -1); the frames after it are served as usual.
    Once the agent has the pipe's shared region (:attr:`lane`), a request
    posted there counts as a frame that arrived (:meth:`receive_nowait` looks
    at the region's doorbell too and hands it over decoded, see
    :func:`~remoteenv.wire.protocol.region_request`), and :meth:`settle` must be called before
    the loop blocks on the pipe, so that requests posted from then on come
    with a frame (:mod:`remoteenv.wire.shared_memory.doorbell`).
    """

    def __init__(self, fd: int) -> None:
        self.sock = socket.socket(fileno=fd)
        self.sock.setblocking(True)
        self._decoder = protocol.StreamDecoder()
        self.closed = False
        self.pollable: Any = self.sock.fileno()
        self.fd: int = self.sock.fileno()
        #: The pipe has no backlog the loop must come back for (see :class:`ZmqChannel`).
        self.more = False
        #: The fast lane of the pipe's shared region, once the agent has it.
        self.lane: LaneWatch | None = None

    def receive_nowait(self) -> list[tuple[Any, Any]]:
        # The region first: a frame the agent sent before it posted there is then read.
        lane = self.lane
        return self._receive(lane.posted() if lane is not None else 0)

    def _receive(self, posted: int) -> list[tuple[Any, Any]]:
        """:meth:`receive_nowait`, the region's posted request (0: none) looked up already."""
        if self.closed:
            return []
        out: list[tuple[Any, Any]] = []
        data = self._decoder.recv_from(self.sock)
        if data is not None:
            if not data:
                self.closed = True
                return []
            for frame in self._decoder.items(data):
                if isinstance(frame, protocol.FrameTooLarge):
                    self.send(None, protocol.pack(protocol.error_reply(-1, PROTOCOL, f"{frame}; dropped unread")))
                else:
                    out.append((None, frame))
        if posted:
            # Its own ring is served once, from the region (decoding and routing it would find it served).
            if out and out[-1][1] == protocol.region_ring(posted):
                out.pop()
            # Served in the agent's order (its seq numbers increase): after the frames sent before it.
            at = len(out)
            while at and protocol.peek_seq(out[at - 1][1]) > posted:
                at -= 1
            out.insert(at, (None, protocol.region_request(posted)))
        return out

    def settle(self) -> list[tuple[Any, Any]]:
        """The loop is about to block: a request posted in the region from now on
        comes with its frame. Returns the one posted meanwhile, if any (then do not block)."""
        lane = self.lane
        if lane is None or self.closed:
            return []
        # A request came meanwhile: take it with the frames the agent sent before it (in order).
        return self.receive_nowait() if lane.settle() else []

    def receive_spinning(self, hot: HotWait) -> list[tuple[Any, Any]]:
        """Like :meth:`receive_nowait`, but busy-wait while ``hot`` (whose
        :meth:`~remoteenv.wire.shared_memory.hot_wait.HotWait.worth_it` said yes) allows.

        Waiting hot avoids the sleep/wake-up of a blocking wait, which on a
        virtual machine costs tens of microseconds per message. It stops when
        the agent says in the region that its caller began a long think. With
        the region's lane it reads the pipe on every :data:`PIPE_LOOK_EVERY`-th
        look only, and whenever a request is posted there (the frames the
        agent sent before it are then served first).
        """
        lane = self.lane
        looks = 0
        while True:
            posted = lane.posted() if lane is not None else 0
            if posted or lane is None or looks % PIPE_LOOK_EVERY == 0:
                frames = self._receive(posted)
                if frames or self.closed:
                    return frames
            looks += 1
            if (lane is not None and lane.agent_away()) or not hot.spin():
                return []

    def send(self, reply_to: Any, payload: bytes) -> None:
        try:
            self.sock.sendall(protocol.stream_frame(payload))
        except OSError:  # the agent is gone; the loop notices the closed pipe
            self.closed = True

    def close(self) -> None:
        self.sock.close()
