"""Whether a DEALER's connection got past the sim's gate, and getting it past.

Runs in the agent process: the agent's ZeroMQ connection
(:class:`~remoteenv.agent.connection.zmq_connection.ZmqConnection`) and the
compliance checker's probe use it. A sim admits a bounded number of
connections at once; its gate refuses the handshake of one more (ZAP status
400, as it refuses a CURVE key it does not list). libzmq ends a connection
whose handshake was refused for good and drops the frames queued on it, so a
client waiting for a reply would wait out its whole timeout, even if a place
came free a moment later.

The watch reads the socket's monitor and sends the client's frames
(:meth:`HandshakeWatch.send`). Until a handshake succeeds it keeps them (none
of them reached the sim: the gate refuses before the sim reads a frame).
After a refusal it connects the same socket again once a pause has passed
(doubling from :data:`REFUSED_PAUSE_S` up to :data:`MAX_REFUSED_PAUSE_S`) and
sends them again, in order. The socket stays
the same object, so pollers holding it keep working. Once a handshake has
succeeded the watch keeps nothing and only records events, for
:meth:`HandshakeWatch.why_failed`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import zmq
from zmq.utils.monitor import recv_monitor_message

#: Seconds before the first new try after a refused handshake (it doubles per refusal).
REFUSED_PAUSE_S = 0.05
#: Longest pause between two tries (seconds).
MAX_REFUSED_PAUSE_S = 1.0
#: Frames kept for a resend while no handshake has succeeded yet; beyond, none is
#: resent (the waiting call times out as it would without the watch).
MAX_KEPT_FRAMES = 64
#: What the monitor records.
WATCHED = (
    zmq.EVENT_DISCONNECTED
    | zmq.EVENT_HANDSHAKE_SUCCEEDED
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
    | zmq.EVENT_HANDSHAKE_FAILED_AUTH
)


class HandshakeWatch:
    """The monitor of one connecting DEALER ``socket`` to ``endpoint``.

    Create it before the socket connects. Send every frame through :meth:`send`,
    call :meth:`look` while waiting for a reply (it never blocks) and
    :meth:`close` before the socket closes.
    """

    def __init__(self, socket: Any, endpoint: str, clock: Callable[[], float] = time.monotonic) -> None:
        self.socket = socket
        self.endpoint = endpoint
        #: Whether a handshake on this socket has succeeded.
        self.admitted = False
        #: Handshakes the sim refused before one succeeded.
        self.refusals = 0
        self._monitor: Any = socket.get_monitor_socket(WATCHED)
        self._clock = clock
        self._kept: list[bytes] | None = []
        self._pause = REFUSED_PAUSE_S
        self._retry_at: float | None = None
        self._seen = 0  # events since why_failed() last looked

    def send(self, frame: bytes) -> None:
        """Send ``frame``, kept for a resend until a handshake succeeds. Blocks as
        the socket's send does (a full queue), never on a refused connection:
        libzmq has no connection to queue on then, and the frame goes with
        the next try."""
        self.look()
        kept = self._kept
        if kept is not None:
            if len(kept) < MAX_KEPT_FRAMES:
                kept.append(frame)
            else:
                self._kept = kept = None
        try:
            self.socket.send(frame, zmq.NOBLOCK, copy=True)
            return
        except zmq.Again:
            pass
        # Nothing to queue on: a refusal the monitor is about to report, or a full queue.
        deadline = self._clock() + REFUSED_PAUSE_S
        while kept is not None and self._monitor is not None and self._retry_at is None and self._clock() < deadline:
            self._monitor.poll(5)
            self._drain()
        if kept is not None and self._retry_at is not None:
            return  # sent with the next try
        self.socket.send(frame, copy=True)

    def look(self) -> None:
        """Read the monitor; after a refused handshake, once the pause has passed,
        connect again and resend the kept frames."""
        if self.admitted:
            return
        self._drain()
        if self._retry_at is not None and self._clock() >= self._retry_at:
            self._retry()

    def why_failed(self, disconnected: str = "the connection to it was closed during the wait") -> str | None:
        """What the monitor saw since the last call that explains a missing reply
        (``disconnected`` when the connection was closed), or None."""
        self._drain()
        seen, self._seen = self._seen, 0
        if seen & zmq.EVENT_HANDSHAKE_FAILED_AUTH:
            return (
                f"the sim refused this connection's ZeroMQ handshake ({self.refusals} time(s) so far): it "
                "serves a bounded number of connections at once, so other clients may hold them all; with "
                "CURVE it also refuses a client key it does not list (check the keys of the launch-info file)"
            )
        if seen & zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL:
            return (
                "its ZeroMQ handshake failed (with CURVE: the server key is not the sim's; check the keys "
                "of the launch-info file)"
            )
        if seen & zmq.EVENT_DISCONNECTED:
            return disconnected
        return None

    def close(self) -> None:
        """Stop the monitor (call before closing the socket)."""
        monitor, self._monitor = self._monitor, None
        if monitor is None:
            return
        try:
            self.socket.disable_monitor()
        except zmq.ZMQError:
            pass
        monitor.close(linger=0)

    def _drain(self) -> None:
        monitor = self._monitor
        while monitor is not None:
            try:
                event = recv_monitor_message(monitor, zmq.NOBLOCK)
            except (zmq.Again, zmq.ZMQError):
                return
            kind = int(event["event"])
            self._seen |= kind
            if kind == zmq.EVENT_HANDSHAKE_SUCCEEDED:
                self.admitted = True
                self._kept = None
                self._seen &= ~(zmq.EVENT_HANDSHAKE_FAILED_AUTH | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL)
                self._retry_at = None
            elif kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH and not self.admitted and self._retry_at is None:
                self.refusals += 1
                self._retry_at = self._clock() + self._pause
                self._pause = min(2 * self._pause, MAX_REFUSED_PAUSE_S)

    def _retry(self) -> None:
        self._retry_at = None
        sock = self.socket
        try:
            sock.disconnect(self.endpoint)
        except zmq.ZMQError:
            pass  # libzmq may have forgotten the ended connection already
        sock.connect(self.endpoint)
        for frame in self._kept or ():
            try:
                sock.send(frame, zmq.NOBLOCK, copy=True)
            except zmq.Again:
                return


__all__ = ["MAX_KEPT_FRAMES", "MAX_REFUSED_PAUSE_S", "REFUSED_PAUSE_S", "HandshakeWatch"]
