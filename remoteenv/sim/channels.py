"""Where a sim process's requests come from: its ZeroMQ ROUTER and its local pipe.

Runs in the sim process. Both channels carry the frames of
:mod:`remoteenv.wire.protocol`; the server's loop treats them alike through
the :class:`Channel` interface: ``receive_nowait`` (the frames that have
arrived, each with whom to answer) and ``send``.
"""

from __future__ import annotations

import socket
from typing import Any, Protocol

import zmq

from remoteenv.sim.limits import FRAMES_PER_DRAIN
from remoteenv.wire import protocol
from remoteenv.wire.errors import PROTOCOL
from remoteenv.wire.hot_wait import HotWait


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

    def receive_nowait(self) -> list[tuple[Any, bytes]]:
        """The request frames that have arrived, each with whom to answer (never blocks)."""
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

    :meth:`receive_nowait` takes at most :data:`~remoteenv.sim.limits.FRAMES_PER_DRAIN`
    frames per call, so a flood cannot keep the loop from its other channels;
    :attr:`more` says whether frames were left waiting.
    """

    def __init__(self, sock: zmq.Socket) -> None:
        self.socket = sock
        self.closed = False
        #: What to register in a ``zmq.Poller``.
        self.pollable: Any = sock
        #: A file descriptor that becomes readable when requests may be waiting
        #: (edge-triggered: always drain with :meth:`receive_nowait`).
        self.fd: int = int(sock.getsockopt(zmq.FD))
        #: True when the last :meth:`receive_nowait` left frames waiting.
        self.more = False

    def receive_nowait(self) -> list[tuple[Any, bytes]]:
        out: list[tuple[Any, bytes]] = []
        sock = self.socket
        handled = 0
        while sock.getsockopt(zmq.EVENTS) & zmq.POLLIN:  # type: ignore[arg-type,operator]
            if handled == FRAMES_PER_DRAIN:
                self.more = True
                return out
            handled += 1
            frames = sock.recv_multipart(zmq.NOBLOCK)
            if len(frames) == 2:  # anything else is not a DEALER-framed request: drop
                out.append((frames[0], frames[1]))
        self.more = False
        return out

    def send(self, reply_to: Any, payload: bytes) -> None:
        self.socket.send_multipart([reply_to, payload])


class PipeChannel:
    """The inherited end of the launcher's socketpair; one peer, no routing id.

    ``closed`` becomes True at end of file (the agent closed its end or died).
    A frame above the frame limit is skipped and answered here with a
    ``protocol`` error (``seq`` -1); the frames after it are served as usual.
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

    def receive_nowait(self) -> list[tuple[Any, bytes]]:
        if self.closed:
            return []
        data = self._decoder.recv_from(self.sock)
        if data is None:
            return []
        if not data:
            self.closed = True
            return []
        out: list[tuple[Any, bytes]] = []
        for frame in self._decoder.items(data):
            if isinstance(frame, protocol.FrameTooLarge):
                self.send(None, protocol.pack(protocol.error_reply(-1, PROTOCOL, f"{frame}; dropped unread")))
            else:
                out.append((None, frame))
        return out

    def receive_spinning(self, hot: HotWait) -> list[tuple[Any, bytes]]:
        """Like :meth:`receive_nowait`, but busy-wait while ``hot`` (whose
        :meth:`~remoteenv.wire.hot_wait.HotWait.worth_it` said yes) allows.

        Waiting hot avoids the sleep/wake-up of a blocking wait, which on a
        virtual machine costs tens of microseconds per message.
        """
        while True:
            frames = self.receive_nowait()
            if frames or self.closed or not hot.spin():
                return frames

    def send(self, reply_to: Any, payload: bytes) -> None:
        try:
            self.sock.sendall(protocol.stream_frame(payload))
        except OSError:  # the agent is gone; the loop notices the closed pipe
            self.closed = True

    def close(self) -> None:
        self.sock.close()
