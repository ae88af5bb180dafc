"""Closing the sim's ZeroMQ socket, its gate and its context, in bounded time.

Runs in the sim process (:meth:`remoteenv.sim.serving.sim_server.RemoteControlledAgent.shutdown`).
libzmq can fail to terminate a context whose socket refused handshakes
through its ZAP handler, on a busy machine (zeromq/libzmq#2733, still open:
a session of the listener never ends, so ``zmq_ctx_term`` waits for good,
whatever the linger). A sim process that exits is not held by that, but a
server in a process that goes on (a test, a program embedding
:class:`~remoteenv.sim.serving.sim_server.RemoteControlledAgent`) would be.
So the gate's stop, the socket's close and the context's termination run
on a daemon thread that the caller waits for at most :data:`CLOSE_WAIT_S`;
past that the caller goes on with a warning, and the thread, should libzmq
ever finish, ends by itself.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

import zmq

from remoteenv.sim.transport.peer_gate import PeerGate

log = logging.getLogger(__name__)

#: Longest wait (seconds) for the gate, the socket and the context to close.
CLOSE_WAIT_S = 5.0


def close_router(
    gate: PeerGate, sock: zmq.Socket[Any], ctx: zmq.Context[Any], instance: int, wait_s: float | None = None
) -> bool:
    """Stop ``gate``, close ``sock`` (linger 0) and terminate ``ctx``, in that
    order, waiting at most ``wait_s`` seconds (None: :data:`CLOSE_WAIT_S`).
    Returns whether all three finished; if not, logs a warning naming sim
    ``instance`` and the step that had not returned."""
    wait_s = CLOSE_WAIT_S if wait_s is None else wait_s
    step = ["stopping the gate"]

    def close() -> None:
        gate.stop()
        step[0] = "closing the socket"
        sock.close(linger=0)
        step[0] = "terminating the context"
        ctx.term()
        step[0] = ""

    closer = threading.Thread(target=close, name=f"remoteenv-router-close-{instance}", daemon=True)
    closer.start()
    closer.join(wait_s)
    if not closer.is_alive():
        return True
    log.warning(
        "sim instance %d: %s did not finish within %.1f s (libzmq can hang there after refusing "
        "handshakes, zeromq/libzmq#2733); going on without it",
        instance,
        step[0],
        wait_s,
    )
    return False


__all__ = ["CLOSE_WAIT_S", "close_router"]
