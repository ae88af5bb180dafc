"""The agent's end of a ZeroMQ connection to one sim (the sim's end is its
:class:`~remoteenv.sim.transport.channels.ZmqChannel`).

Runs in the agent process. A DEALER socket to the sim's ROUTER. After a
timeout the socket is thrown away and a new one connected, so the next call
starts clean (the zguide's "Lazy Pirate" pattern). The new socket keeps the
connection's random routing id, so a real-time sim still knows it as the
connection that drives its world. A handshake the sim's gate refused (it
serves a bounded number of connections at once) is tried again after a
short pause, with the frames sent meanwhile
(:class:`~remoteenv.agent.connection.handshake_watch.HandshakeWatch`).

Memory: the socket queues at most :data:`RECEIVE_HWM` frames from the sim
(libzmq stops reading a peer whose queue is full; the sim's own send queue
takes the rest) and drops a frame above the wire's frame limit
(``ZMQ_MAXMSGSIZE``, which closes that connection), so whatever the sim
sends, the socket holds at most ``(RECEIVE_HWM + 1) x MAX_MESSAGE_BYTES``.
The watch's monitor records such dropped connections and failed
ZeroMQ/CURVE handshakes, so a timeout that follows names them.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import zmq

from remoteenv.agent.connection.handshake_watch import HandshakeWatch
from remoteenv.agent.connection.sim_connection import LIVENESS_CHECK_S, SimConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire import protocol
from remoteenv.wire.files.keys import check_key
from remoteenv.wire.wire_errors import short_repr

#: Frames from the sim the socket queues before libzmq stops reading it (a
#: vector env has one request in flight per sim, ``send()``/``recv()`` a few).
RECEIVE_HWM = 4


class ZmqConnection(SimConnection):
    """Request/reply channel to one sim process over ZeroMQ (a DEALER socket).

    Args:
        endpoint: the sim's bound ZeroMQ endpoint.
        instance, timeout, death_check: as for :class:`SimConnection`.
        curve_server_key: the sim's public Z85 CURVE key; enables encryption.
        curve_client_keypair: ``(public, secret)`` Z85 client keys the sim
            admits; default a fresh pair (enough for a sim that admits any client).
    """

    def __init__(
        self,
        endpoint: str,
        *,
        instance: int = 0,
        timeout: float | None = 60.0,
        death_check: Callable[[], str | None] | None = None,
        curve_server_key: bytes | None = None,
        curve_client_keypair: tuple[bytes, bytes] | None = None,
    ) -> None:
        super().__init__(endpoint, instance=instance, timeout=timeout, death_check=death_check)
        self.curve_server_key = curve_server_key
        self.curve_client_keypair = curve_client_keypair
        self.socket: Any = None
        self._watch: HandshakeWatch | None = None
        # Routing ids starting with a zero byte are reserved by ZeroMQ.
        self.routing_id = b"\x01" + os.urandom(15)
        self._open()

    def _open(self) -> None:
        sock: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.DEALER)
        try:
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.RECONNECT_IVL, 20)
            sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
            sock.setsockopt(zmq.RCVHWM, RECEIVE_HWM)
            sock.setsockopt(zmq.RCVTIMEO, int(LIVENESS_CHECK_S * 1000))
            sock.setsockopt(zmq.ROUTING_ID, self.routing_id)
            if self.curve_server_key is not None:
                public, secret = self.curve_client_keypair or zmq.curve_keypair()
                sock.curve_serverkey = self._key(self.curve_server_key, "server public key")
                sock.curve_publickey = self._key(public, "client public key")
                sock.curve_secretkey = self._key(secret, "client secret key")
            self._watch = HandshakeWatch(sock, self.endpoint)
            sock.connect(self.endpoint)
        except BaseException as exc:
            self._close_socket(sock)
            if isinstance(exc, RemoteEnvError) or not isinstance(exc, (zmq.ZMQError, TypeError, ValueError)):
                raise
            # ZMQError's text repeats the whole address: name the error alone.
            reason = zmq.strerror(exc.errno or 0) if isinstance(exc, zmq.ZMQError) else short_repr(str(exc))
            raise RemoteEnvError(
                f"cannot connect to sim instance {self.instance}: endpoint {short_repr(self.endpoint)} is not "
                f"one ZeroMQ can reach ({reason}); expected e.g. tcp://127.0.0.1:5555 or ipc:///path/sim-0.sock",
                kind="launch",
                instance=self.instance,
            ) from None
        self.socket = sock

    def _key(self, key: bytes | str, what: str) -> bytes:
        try:
            return check_key(key, what)
        except ValueError as exc:
            raise RemoteEnvError(
                f"cannot connect to sim instance {self.instance} at {short_repr(self.endpoint)}: "
                f"its CURVE {what} is not usable ({exc})",
                kind="launch",
                instance=self.instance,
            ) from None

    @property
    def pollable(self) -> Any:
        return self.socket

    def _send_frame(self, payload: bytes) -> None:
        if self._watch is not None:
            self._watch.send(payload)
        else:
            self.socket.send(payload, copy=True)

    def _check_alive(self, what: str) -> None:
        # Called while a reply is awaited and none came for a while: a refused handshake is tried again.
        watch = self._watch
        if watch is not None:
            watch.look()
        super()._check_alive(what)

    def _recv_frame(self) -> bytes | None:
        try:
            return self.socket.recv(copy=True)
        except zmq.Again:
            return None

    def _recv_frame_nowait(self) -> bytes | None:
        try:
            return self.socket.recv(zmq.NOBLOCK, copy=True)
        except zmq.Again:
            return None

    def _after_timeout(self) -> None:
        self.reconnect()

    def why_silent(self) -> str | None:
        """What the monitor saw since the last look: a refused or failed handshake
        (too many clients? CURVE keys?) or a dropped connection while the sim
        lives (e.g. its reply was above the frame limit: libzmq closes such a connection)."""
        if self._watch is None:
            return None
        return self._watch.why_failed(
            disconnected=(
                "the connection to it was closed during the wait: if the server still runs, most likely "
                f"because its reply was above the wire's frame limit of {protocol.MAX_MESSAGE_BYTES >> 20} MiB "
                "(remoteenv.wire.protocol.MAX_MESSAGE_BYTES), which the agent refuses by closing the "
                "connection (the reply is lost); else the server stopped"
            )
        )

    def reconnect(self) -> None:
        """Drop the socket (and anything queued on it) and connect afresh."""
        if self.socket is not None:
            self._close_socket(self.socket)
            self.socket = None
        self._open()

    def close(self) -> None:
        super().close()
        if self.socket is not None:
            self._close_socket(self.socket)
            self.socket = None

    def _close_socket(self, sock: Any) -> None:
        if self._watch is not None:
            self._watch.close()
            self._watch = None
        sock.close(linger=0)


__all__ = ["RECEIVE_HWM", "ZmqConnection"]
