"""Connections from the agent to its sims, and which one to open.

Runs in the agent process. One request/reply logic
(:class:`~remoteenv.agent.connection.sim_connection.SimConnection`: sequence numbers,
stale replies dropped, timeouts, typed errors, a dead peer noticed within
:data:`LIVENESS_CHECK_S`) over two transports:

- :class:`~remoteenv.agent.connection.zmq_connection.ZmqConnection`: ZeroMQ, to any sim
  at any endpoint (with CURVE when the sim has a server key). Also importable
  here under its former name, ``Connection``.
- :class:`~remoteenv.agent.connection.pipe_connection.PipeConnection`: the local pipe
  to a sim this process launched; the fastest.

:func:`connect_sim` picks the pipe when the sim has one.
"""

from __future__ import annotations

from typing import Any

from remoteenv.agent.connection.pipe_connection import PipeConnection
from remoteenv.agent.connection.sim_connection import LIVENESS_CHECK_S, SimConnection
from remoteenv.agent.connection.zmq_connection import ZmqConnection
from remoteenv.wire.files.keys import KeyPair

#: The former name of :class:`ZmqConnection`.
Connection = ZmqConnection


def connect_sim(
    sim: Any,
    *,
    timeout: float | None = 60.0,
    curve_client_keypair: KeyPair | None = None,
) -> SimConnection:
    """A connection to ``sim`` (a :class:`~remoteenv.agent.launch.sim_group.SimHandle`:
    a launched or an attached sim): over its local pipe if it has one, else
    over ZeroMQ, with CURVE when the sim has a server key.
    ``curve_client_keypair`` is the group's
    :attr:`~remoteenv.agent.launch.sim_group.SimGroup.curve_client_keypair` or None."""
    death_check = getattr(sim, "death", None)
    pipe = getattr(sim, "pipe", None)
    if pipe is not None:
        return PipeConnection(
            pipe,
            endpoint=sim.endpoint or "",
            instance=sim.instance,
            timeout=timeout,
            death_check=death_check,
            pid=getattr(sim, "pid", None),
        )
    return ZmqConnection(
        sim.endpoint or "",
        instance=sim.instance,
        timeout=timeout,
        death_check=death_check,
        curve_server_key=getattr(sim, "curve_server_key", None),
        curve_client_keypair=None
        if curve_client_keypair is None
        else (curve_client_keypair.public, curve_client_keypair.secret),
    )


__all__ = ["LIVENESS_CHECK_S", "Connection", "PipeConnection", "SimConnection", "ZmqConnection", "connect_sim"]
