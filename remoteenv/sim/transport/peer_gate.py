"""The gate of a sim's ZeroMQ socket: at most :data:`~remoteenv.sim.transport.limits.MAX_PEERS`
connections at once, and with CURVE client keys only the listed clients.

Runs in the sim process, on a thread of its own. libzmq admits any number of
connections to a ROUTER and queues up to ``RCVHWM`` frames for each, so the
memory a flood can pin grows with the number of peers. The gate is the
socket's ZAP handler (RFC 27, asked for every new connection's handshake,
NULL mechanism included once the socket has a ZAP domain): it refuses a
handshake while ``MAX_PEERS`` admitted connections are open, which makes the
memory bound total instead of per peer. A refused peer gets no connection:
libzmq ends it for good (no reconnect) and drops what was queued on it, so a
client that wants in connects again itself (remoteenv's agent connection
and the checker's probe do, see ``remoteenv/agent/connection/handshake_watch.py``).

libzmq does not tell the ZAP handler which connection asks, nor when an
admitted one ends; the socket monitor does, in counts:
``HANDSHAKE_SUCCEEDED`` and ``HANDSHAKE_FAILED_*`` end a handshake (one of them
per connection, the failure followed at once by that connection's
``DISCONNECTED``), and every connection ends with ``DISCONNECTED``. So the
open admitted connections are ``succeeded + failed - disconnected``
(handshakes that failed are disconnected too), capped by the connections
open at all (``ACCEPTED`` minus ``DISCONNECTED``, by descriptor: it heals
itself when the socket has no connection left). Admissions whose handshake
has not finished yet count as well, for at most the handshake interval.
"""

from __future__ import annotations

import collections
import itertools
import threading
import time
from typing import Any

import zmq
from zmq.utils import z85
from zmq.utils.monitor import parse_monitor_message

#: The ZAP endpoint libzmq asks (one per context: each server has its own context).
ZAP_ENDPOINT = "inproc://zeromq.zap.01"
#: The ZAP domain set on the server's socket (turns ZAP on for the NULL mechanism).
ZAP_DOMAIN = b"remoteenv"
_FAILED = (
    zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL,
    zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL,
    zmq.EVENT_HANDSHAKE_FAILED_AUTH,
)
_EVENTS = zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED | zmq.EVENT_HANDSHAKE_SUCCEEDED
for _event in _FAILED:
    _EVENTS |= _event
_gates = itertools.count()


class PeerCount:
    """The count of open admitted connections, from the socket's monitor events
    and the gate's own admissions (see the module docstring). Pure bookkeeping."""

    def __init__(self, handshake_s: float) -> None:
        self.handshake_s = handshake_s
        self._open: set[int] = set()
        self._admitted = 0
        self._pending: collections.deque[float] = collections.deque()

    def event(self, event: int, value: int) -> None:
        """One monitor event (``value``: the descriptor for accepted/disconnected)."""
        if event == zmq.EVENT_ACCEPTED:
            self._open.add(value)
        elif event == zmq.EVENT_DISCONNECTED:
            self._open.discard(value)
            self._admitted -= 1
        elif event == zmq.EVENT_HANDSHAKE_SUCCEEDED:
            self._admitted += 1
            if self._pending:
                self._pending.popleft()
        elif event in _FAILED:
            self._admitted += 1  # its DISCONNECTED follows
        if not self._open:
            self._admitted = 0
            self._pending.clear()
        self._admitted = min(max(self._admitted, 0), len(self._open))

    def admitted(self, now: float) -> int:
        """Open admitted connections, counting admissions still in their handshake."""
        pending = self._pending
        while pending and now - pending[0] > self.handshake_s:
            pending.popleft()
        return self._admitted + len(pending)

    def admit(self, now: float) -> None:
        """The gate admitted a connection whose handshake now completes."""
        self._pending.append(now)


class PeerGate:
    """The ZAP handler and monitor of one server socket, on a thread.

    Create it before the socket binds (it sets the socket's ZAP domain and
    monitor); :meth:`stop` it before closing the socket.

    Args:
        ctx: the server's own context (one ZAP handler per context).
        sock: the server's ROUTER socket.
        max_peers: connections admitted at once.
        handshake_s: the socket's handshake interval (seconds).
        client_keys: with CURVE, the Z85 public keys of the admitted clients;
            None admits any client that completes the handshake.
    """

    def __init__(
        self,
        ctx: zmq.Context[Any],
        sock: zmq.Socket[Any],
        max_peers: int,
        handshake_s: float,
        client_keys: list[bytes] | None = None,
    ) -> None:
        self.max_peers = max_peers
        self.count = PeerCount(handshake_s)
        self.refused = 0
        #: Descriptors of connections that ended, oldest first (taken by :meth:`take_disconnected`).
        self._disconnected: collections.deque[int] = collections.deque(maxlen=4 * max_peers + 64)
        self._keys = None if client_keys is None else frozenset(z85.decode(bytes(k).strip()) for k in client_keys)
        self._ctx = ctx
        self._monitor = f"inproc://remoteenv-peer-monitor-{next(_gates)}"
        self._stop = f"inproc://remoteenv-peer-gate-stop-{next(_gates)}"
        sock.setsockopt(zmq.ZAP_DOMAIN, ZAP_DOMAIN)
        sock.monitor(self._monitor, _EVENTS)
        self._sock = sock
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name="remoteenv-peer-gate", daemon=True)
        self._thread.start()
        self._ready.wait()
        self._stopper = ctx.socket(zmq.PAIR)
        self._stopper.setsockopt(zmq.LINGER, 0)
        self._stopper.connect(self._stop)

    def take_disconnected(self) -> list[int]:
        """The descriptors of the connections that ended since the last call (any thread)."""
        gone = []
        while self._disconnected:
            gone.append(self._disconnected.popleft())
        return gone

    def stop(self) -> None:
        """End the monitor, then the thread (call before the socket closes).

        The monitor goes first, while the thread still reads its events:
        libzmq hands each event to the monitor with a send that waits for a
        reader, under a lock that ``disable_monitor`` takes too, so a peer
        that came or went after the thread had stopped reading left
        ``disable_monitor`` waiting for good (seen once in CI, 2026-11-29)."""
        try:
            self._sock.disable_monitor()
        except zmq.ZMQError:
            pass
        if self._thread.is_alive():
            self._stopper.send(b"")
            self._thread.join()
        self._stopper.close(linger=0)

    # ------------------------------------------------------------ the thread

    def _run(self) -> None:
        ctx = self._ctx
        zap = ctx.socket(zmq.REP)
        events = ctx.socket(zmq.PAIR)
        stop = ctx.socket(zmq.PAIR)
        for s in (zap, events, stop):
            s.setsockopt(zmq.LINGER, 0)
        zap.bind(ZAP_ENDPOINT)
        events.connect(self._monitor)
        stop.bind(self._stop)
        poller = zmq.Poller()
        for s in (zap, events, stop):
            poller.register(s, zmq.POLLIN)
        self._ready.set()
        try:
            while True:
                ready = dict(poller.poll())
                if stop in ready:
                    return
                while events.poll(0):  # count connections first: the freshest figure
                    event = parse_monitor_message(events.recv_multipart())
                    self.count.event(event["event"], event["value"])
                    if event["event"] == zmq.EVENT_DISCONNECTED:
                        self._disconnected.append(int(event["value"]))
                if zap in ready:
                    zap.send_multipart(self._answer(zap.recv_multipart()))
        finally:
            for s in (zap, events, stop):
                s.close(linger=0)

    def _answer(self, request: list[bytes]) -> list[bytes]:
        """The ZAP reply to one request (RFC 27): 200 admits, 400 refuses."""
        if len(request) < 6 or request[0] != b"1.0":
            return [b"1.0", request[1] if len(request) > 1 else b"", b"500", b"malformed ZAP request", b"", b""]
        request_id, mechanism, credentials = request[1], request[5], request[6:]
        if self._keys is not None and (mechanism != b"CURVE" or not credentials or credentials[0] not in self._keys):
            return [b"1.0", request_id, b"400", b"client key not admitted", b"", b""]
        now = time.monotonic()
        if self.count.admitted(now) >= self.max_peers:
            self.refused += 1
            return [b"1.0", request_id, b"400", b"too many connections", b"", b""]
        self.count.admit(now)
        return [b"1.0", request_id, b"200", b"OK", b"", b""]


__all__ = ["PeerCount", "PeerGate", "ZAP_DOMAIN", "ZAP_ENDPOINT"]
