"""The agent's end of a ZeroMQ connection to one sim (the sim's end is its
:class:`~remoteenv.sim.channels.ZmqChannel`).

Runs in the agent process. A DEALER socket to the sim's ROUTER. After a
timeout the socket is thrown away and a new one connected, so the next call
starts clean (the zguide's "Lazy Pirate" pattern). The new socket keeps the
connection's random routing id, so a real-time sim still knows it as the
connection that drives its world.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import zmq

from remoteenv.agent.sim_connection import LIVENESS_CHECK_S, SimConnection
from remoteenv.wire import protocol


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
        # Routing ids starting with a zero byte are reserved by ZeroMQ.
        self.routing_id = b"\x01" + os.urandom(15)
        self._open()

    def _open(self) -> None:
        sock: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RECONNECT_IVL, 20)
        sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
        sock.setsockopt(zmq.RCVTIMEO, int(LIVENESS_CHECK_S * 1000))
        sock.setsockopt(zmq.ROUTING_ID, self.routing_id)
        if self.curve_server_key is not None:
            public, secret = self.curve_client_keypair or zmq.curve_keypair()
            sock.curve_serverkey = self.curve_server_key
            sock.curve_publickey = public
            sock.curve_secretkey = secret
        sock.connect(self.endpoint)
        self.socket = sock

    @property
    def pollable(self) -> Any:
        return self.socket

    def _send_frame(self, payload: bytes) -> None:
        self.socket.send(payload, copy=True)

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

    def reconnect(self) -> None:
        """Drop the socket (and anything queued on it) and connect afresh."""
        if self.socket is not None:
            self.socket.close(linger=0)
        self._open()

    def close(self) -> None:
        super().close()
        if self.socket is not None:
            self.socket.close(linger=0)
            self.socket = None


__all__ = ["ZmqConnection"]
