"""The limits that keep a sim process's memory, descriptors and CPU bounded
whatever reaches its ZeroMQ endpoint.

Runs in the sim process. Memory held for requests that came over ZeroMQ is
at most, per connected peer, ``(ROUTER_RCVHWM + 1) * MAX_MESSAGE_BYTES`` (the
queued frames plus one being received; libzmq stops reading a peer whose
queue is full, so a flood backs up into the flooder's own queues), and the
same again for replies queued to a peer that does not read them
(``ROUTER_SNDHWM``: further replies to that peer are dropped). The server's
loop handles at most ``FRAMES_PER_DRAIN`` ZeroMQ frames before it serves the
local pipe again. With CURVE on, a peer that has not completed its handshake
can queue nothing. A connection that has not completed the ZeroMQ handshake
within ``HANDSHAKE_IVL_S`` is closed, and the soft descriptor limit is raised
to the hard one, so a storm of idle connections neither exhausts descriptors
nor keeps the I/O thread spinning on failed accepts. See ``docs/security.md``.
"""

from __future__ import annotations

import resource
from typing import Any

import zmq

from remoteenv.wire.protocol import MAX_MESSAGE_BYTES

#: Frames a peer may have queued towards the sim (libzmq stops reading it beyond).
ROUTER_RCVHWM = 16
#: Replies queued towards one peer that does not read them; later ones are
#: dropped (a client may pipeline up to this many requests and read them all).
ROUTER_SNDHWM = 128
#: Seconds a connection gets to complete the ZeroMQ (and CURVE) handshake.
HANDSHAKE_IVL_S = 2.0
#: ZeroMQ frames the server's loop handles before it serves its other channels.
FRAMES_PER_DRAIN = 32


def configure_router(sock: zmq.Socket[Any]) -> None:
    """Set the limits above on the sim's ROUTER socket (before it binds).

    ``ROUTER_HANDOVER`` lets an agent that reconnects with its routing id
    (after a timeout) take its place back at once.
    """
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
    sock.setsockopt(zmq.RCVHWM, ROUTER_RCVHWM)
    sock.setsockopt(zmq.SNDHWM, ROUTER_SNDHWM)
    sock.setsockopt(zmq.HANDSHAKE_IVL, round(HANDSHAKE_IVL_S * 1000))
    sock.setsockopt(zmq.ROUTER_HANDOVER, 1)


def raise_fd_limit() -> int:
    """Raise this process's soft limit of open files to its hard limit; the new soft limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard == resource.RLIM_INFINITY:
        hard = max(soft, 1 << 20) if soft != resource.RLIM_INFINITY else soft
    if soft != resource.RLIM_INFINITY and soft < hard:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))
            soft = hard
        except (ValueError, OSError):
            pass
    return int(soft)


__all__ = [
    "FRAMES_PER_DRAIN",
    "HANDSHAKE_IVL_S",
    "ROUTER_RCVHWM",
    "ROUTER_SNDHWM",
    "configure_router",
    "raise_fd_limit",
]
