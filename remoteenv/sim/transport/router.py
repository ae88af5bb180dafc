"""The sim's ZeroMQ socket: a ROUTER with the limits of :mod:`remoteenv.sim.transport.limits`,
behind its gate (:mod:`remoteenv.sim.transport.peer_gate`), with CURVE when asked.

Runs in the sim process.
"""

from __future__ import annotations

from typing import Any

import zmq

from remoteenv.sim.transport.limits import HANDSHAKE_IVL_S, MAX_PEERS, configure_router
from remoteenv.sim.transport.peer_gate import PeerGate
from remoteenv.wire.addresses import is_loopback


def open_router(
    ctx: zmq.Context[Any],
    address: str,
    curve_secret_key: bytes | None = None,
    curve_client_keys: list[bytes] | None = None,
) -> tuple[zmq.Socket[Any], PeerGate]:
    """A ROUTER bound at ``address`` in ``ctx`` (the server's own context: its
    gate is the context's ZAP handler) and its running gate.

    With ``curve_secret_key`` the socket is a CURVE server and, with
    ``curve_client_keys``, admits only those clients; without it ``address``
    must be loopback or ipc. Raises ``ValueError`` for a non-loopback address
    without CURVE, ``zmq.ZMQError`` if binding fails (nothing is left open).
    """
    if curve_secret_key is None and not is_loopback(address):
        raise ValueError(f"binding {address!r} beyond loopback requires CURVE keys")
    sock = ctx.socket(zmq.ROUTER)
    gate = None
    try:
        configure_router(sock)
        if curve_secret_key is not None:
            sock.curve_server = True
            sock.curve_secretkey = curve_secret_key
        gate = PeerGate(ctx, sock, MAX_PEERS, HANDSHAKE_IVL_S, curve_client_keys)
        sock.bind(address)
    except BaseException:
        if gate is not None:
            gate.stop()
        sock.close(linger=0)
        raise
    return sock, gate


__all__ = ["open_router"]
