"""Waiting for the replies of many sims at once (the fan-in of a vector call).

Runs in the agent process. A vector env sends one request to each of its sim
processes, then :class:`FanIn` collects the replies with one ``zmq.Poller``
over their connections, so the processes compute in parallel. While replies
have been quick it polls without sleeping first (adaptive, see
:mod:`remoteenv.wire.shared_memory.hot_wait`); local pipes are read in turn instead, one
blocking read per reply (fewer system calls); stale replies (to abandoned
requests) are dropped as they come, a bounded number per connection and
round, and the deadline is checked on every round whatever arrived; a dead sim is reported within
:data:`~remoteenv.agent.connection.sim_connection.LIVENESS_CHECK_S`; after the timeout
the connections still pending are rebuilt and :class:`remoteenv.RemoteEnvTimeout`
is raised.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import zmq

from remoteenv.agent.connection.sim_connection import LIVENESS_CHECK_S, SimConnection
from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.wire.shared_memory.hot_wait import HotWait

#: Longest busy-wait (seconds) of a vector call for its replies before sleeping;
#: calls whose replies took longer sleep at once (the sims need the CPUs).
GATHER_SPIN_S = 250e-6

#: ``seq`` no request ever has: asking for it drains (and drops) stale replies.
_NO_SEQ = -2


class FanIn:
    """Gathers replies from many connections; keeps its poller between calls.

    Connections whose :attr:`~remoteenv.agent.connection.sim_connection.SimConnection.pollable`
    is None (in-process transports) are asked directly on every round.
    """

    def __init__(self, spin_s: float = GATHER_SPIN_S) -> None:
        self._hot = HotWait(spin_s)
        self._poller: zmq.Poller | None = None
        self._poll_socks: list[Any] = []
        self._socket_index: dict[Any, int] = {}
        self._unpolled: list[int] = []

    def forget(self) -> None:
        """Drop the cached poller (a connection was replaced)."""
        self._poller = None

    def gather(
        self,
        conns: Sequence[SimConnection],
        pending: dict[int, int],
        what: str,
        timeout: float | None,
        replies: dict[int, dict[str, Any]],
    ) -> None:
        """Wait for the reply to each ``{index: seq}`` in ``pending`` (``conns[index]``
        sent it), all in flight at once. Each reply goes into ``replies`` and its
        index leaves ``pending`` as it arrives; ``timeout`` bounds the whole wait
        (seconds, None: no bound). Raises the first failure (a sim's error reply,
        a death, the timeout)."""
        if len(pending) == 1:
            ((p, seq),) = pending.items()
            replies[p] = conns[p].receive(seq, timeout, what=what)
            del pending[p]
            return
        deadline = None if timeout is None else time.monotonic() + timeout
        if all(conns[p].waits_in_turn for p in pending):
            self._gather_in_turn(conns, pending, what, timeout, deadline, replies)
            return
        poller = self._poller_for(conns)
        socket_index, unpolled = self._socket_index, self._unpolled
        hot = self._hot
        started = time.perf_counter()
        spinning = hot.worth_it() and not unpolled
        idle_wait_ms = 0 if unpolled else int(LIVENESS_CHECK_S * 1000)
        while pending:
            # While replies have been quick (and no busy neighbour stalled a
            # spin), poll without sleeping first, yielding the CPU as we go.
            events = poller.poll(0)
            while not events and spinning:
                spinning = hot.spin()
                events = poller.poll(0)
            if not events:
                events = poller.poll(idle_wait_ms)
            arrived = False
            for sock, _ in events:
                arrived |= self._take(conns, socket_index[sock], pending, what, replies)
            for p in unpolled:
                arrived |= self._take(conns, p, pending, what, replies)
            if not events and not arrived:
                for p in pending:
                    conns[p].check_alive(what)
            # Checked on every round, whatever arrived: stale frames never extend it.
            if pending and deadline is not None and time.monotonic() > deadline:
                self._time_out(conns, pending, what, timeout)
        hot.waited(time.perf_counter() - started)

    # ------------------------------------------------------------ internals

    def _gather_in_turn(
        self,
        conns: Sequence[SimConnection],
        pending: dict[int, int],
        what: str,
        timeout: float | None,
        deadline: float | None,
        replies: dict[int, dict[str, Any]],
    ) -> None:
        """Local pipes: wait for each reply in turn, one blocking read each (the
        processes still compute in parallel); every :data:`LIVENESS_CHECK_S`
        without a reply, every pending sim is checked for life."""
        for p in list(pending):
            while True:
                reply = conns[p].try_receive(pending[p], what, wait=True)
                if reply is not None:
                    replies[p] = reply
                    del pending[p]
                    break
                for q in pending:
                    conns[q].check_alive(what)
                if deadline is not None and time.monotonic() > deadline:
                    self._time_out(conns, pending, what, timeout)

    @staticmethod
    def _take(
        conns: Sequence[SimConnection], p: int, pending: dict[int, int], what: str, replies: dict[int, dict[str, Any]]
    ) -> bool:
        """Read what connection ``p`` has; True if its awaited reply came."""
        seq = pending.get(p)
        if seq is None:
            try:
                conns[p].try_receive(_NO_SEQ, what)  # drop stale replies
            except RemoteEnvError:
                pass
            return False
        reply = conns[p].try_receive(seq, what)
        if reply is None:
            return False
        replies[p] = reply
        del pending[p]
        return True

    def _time_out(
        self, conns: Sequence[SimConnection], pending: dict[int, int], what: str, timeout: float | None
    ) -> None:
        p = next(iter(pending))
        why = conns[p].why_silent() or (
            "the process is alive but stuck or overloaded. Raise the vector env's timeout= or check the scene code"
        )
        for q in pending:
            conns[q].reconnect()
        self._poller = None
        raise RemoteEnvTimeout(
            f"sim instance {p} (and {len(pending) - 1} more) at {conns[p].endpoint} "
            f"did not answer {what} within {timeout:g} s; {why}. "
            "The connections were rebuilt; the next call can go ahead.",
            kind="timeout",
            instance=p,
        )

    def _poller_for(self, conns: Sequence[SimConnection]) -> zmq.Poller:
        socks = [c.pollable for c in conns]
        if self._poller is None or socks != self._poll_socks:
            poller = zmq.Poller()
            for sock in socks:
                if sock is not None:
                    poller.register(sock, zmq.POLLIN)
            self._poller, self._poll_socks = poller, socks
            self._socket_index = {sock: p for p, sock in enumerate(socks) if sock is not None}
            self._unpolled = [p for p, sock in enumerate(socks) if sock is None]
        return self._poller


__all__ = ["GATHER_SPIN_S", "FanIn"]
