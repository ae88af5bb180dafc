"""The limits that keep a sim process's memory, descriptors and CPU bounded
whatever reaches its ZeroMQ endpoint, with the owner served first.

Runs in the sim process. Memory for requests that came over ZeroMQ is
bounded in total, not per peer:

- at most :data:`MAX_PEERS` connections are admitted at once (the socket's
  ZAP handler refuses further handshakes: :mod:`remoteenv.sim.transport.peer_gate`);
- per admitted connection libzmq queues at most :data:`ROUTER_RCVHWM` frames
  and holds about two more (one decoded that did not fit the queue, one
  being read), each at most ``MAX_MESSAGE_BYTES``; past that it stops reading
  the peer, so a flood backs up into the flooder's own buffers;
- the server's loop takes at most :data:`FRAMES_PER_DRAIN` frames per pass
  out of libzmq, serves the frames of the connections that drive a world at
  once, and keeps other connections' frames in a backlog of at most
  :data:`BACKLOG_BYTES` (or one frame, if larger), from which it serves
  :data:`OTHERS_BYTES_PER_PASS` (at least one frame) and at most
  :data:`EXPENSIVE_PER_PASS` of :data:`EXPENSIVE_COMMANDS` per pass; a frame
  that finds the backlog full is dropped unread and answered with a
  ``state`` error (``busy``).

So requests held for ZeroMQ peers never exceed
``MAX_PEERS * (ROUTER_RCVHWM + 2) * MAX_MESSAGE_BYTES + BACKLOG_BYTES``
(:func:`request_memory_bound`), replies at most ``ROUTER_SNDHWM`` per peer
(further replies to a peer that does not read are dropped). With CURVE on,
a peer that has not completed its handshake can queue nothing; a connection
that has not completed the ZeroMQ handshake within :data:`HANDSHAKE_IVL_S` is
closed, and the soft descriptor limit is raised to the hard one, so a storm
of idle connections neither exhausts descriptors nor keeps the I/O thread
spinning on failed accepts. Large buffers are returned to the system when
freed (:func:`return_large_frees`). See ``docs/security.md``.
"""

from __future__ import annotations

import ctypes
import resource
from typing import Any

import zmq

from remoteenv.wire.protocol import MAX_MESSAGE_BYTES

#: ZeroMQ connections (admitted handshakes) a sim serves at once.
MAX_PEERS = 8
#: Frames a peer may have queued towards the sim (libzmq stops reading it beyond).
ROUTER_RCVHWM = 4
#: Replies queued towards one peer that does not read them; later ones are
#: dropped (a client may pipeline up to this many requests and read them all).
ROUTER_SNDHWM = 128
#: Seconds a connection gets to complete the ZeroMQ (and CURVE) handshake.
HANDSHAKE_IVL_S = 2.0
#: ZeroMQ frames the server's loop takes out of libzmq per pass.
FRAMES_PER_DRAIN = 32
#: Bytes of requests from connections that drive no world, kept waiting at most.
BACKLOG_BYTES = 64 << 20
#: Bytes of such requests served per pass of the loop (always at least one request).
OTHERS_BYTES_PER_PASS = 1 << 20
#: Commands whose cost does not show in their size (a render, scene code behind
#: an attribute); served per pass at most :data:`EXPENSIVE_PER_PASS` times for
#: connections that drive no world.
EXPENSIVE_COMMANDS = frozenset({"render", "get_attr", "set_attr", "call"})
#: Expensive requests of connections that drive no world served per pass.
EXPENSIVE_PER_PASS = 1
#: Allocations at least this large (bytes) get their own mapping, returned to
#: the system when freed (glibc's ``M_MMAP_THRESHOLD``; see :func:`return_large_frees`).
LARGE_ALLOCATION_BYTES = 1 << 20


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


def request_memory_bound() -> int:
    """Bytes of ZeroMQ requests a sim holds at most (see the module docstring)."""
    return MAX_PEERS * (ROUTER_RCVHWM + 2) * MAX_MESSAGE_BYTES + max(BACKLOG_BYTES, MAX_MESSAGE_BYTES)


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


def return_large_frees() -> bool:
    """Make freed allocations of :data:`LARGE_ALLOCATION_BYTES` or more go back to the system.

    glibc serves a large allocation from its own mapping only up to a
    threshold that rises to the largest block freed so far (at most 32 MiB),
    so after a flood of multi-MiB frames the process's heaps keep gigabytes
    that are free but never returned. A fixed threshold keeps every frame-sized
    buffer in a mapping of its own, unmapped when freed. True if it was set
    (glibc only; elsewhere nothing changes).
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt  # this process's own symbols: libc's, if it is glibc
    except (OSError, AttributeError, TypeError):
        return False
    m_mmap_threshold = -3
    return bool(mallopt(ctypes.c_int(m_mmap_threshold), ctypes.c_int(LARGE_ALLOCATION_BYTES)))


__all__ = [
    "BACKLOG_BYTES",
    "EXPENSIVE_COMMANDS",
    "EXPENSIVE_PER_PASS",
    "FRAMES_PER_DRAIN",
    "HANDSHAKE_IVL_S",
    "LARGE_ALLOCATION_BYTES",
    "MAX_PEERS",
    "OTHERS_BYTES_PER_PASS",
    "ROUTER_RCVHWM",
    "ROUTER_SNDHWM",
    "configure_router",
    "raise_fd_limit",
    "request_memory_bound",
    "return_large_frees",
]
