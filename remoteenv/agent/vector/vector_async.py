"""EnvPool's asynchronous API for a vector env: send actions for some worlds,
receive the first ones to finish.

Runs in the agent process (:meth:`remoteenv.RemoteVectorEnv.send` and
:meth:`~remoteenv.RemoteVectorEnv.recv`). :meth:`AsyncWorlds.send` sends one
``step_batch`` (with its ``worlds`` field) to each process hosting some of
the given worlds, at once, without waiting; a process may have several
requests in flight and answers them in order. :meth:`AsyncWorlds.recv`
waits until replies for at least ``batch_size`` worlds have arrived and
returns exactly ``batch_size`` of them, earliest first, keeping the rest for
the next call. So while the policy computes actions for one batch, the sims
step the others.

Replies come per request: a process's worlds of one request finish
together. Failures are raised (``restart_on_failure`` covers ``step`` and
``step_wait`` only) after everything in flight is forgotten: the worlds'
state is then unknown, and the env needs a ``reset()``.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np
import zmq

from remoteenv.agent.connection.shared_lane_client import RegionReply, SharedLanes
from remoteenv.agent.connection.sim_connection import LIVENESS_CHECK_S
from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout, StateError
from remoteenv.agent.session.sim_session import SimSession
from remoteenv.agent.vector.vector_results import ObsBatch, assemble
from remoteenv.wire.messages.batch_encoding import AddInfo

#: One reply's worth of worlds: their global ids, their ops and the ``step_batch`` reply.
Chunk = tuple[np.ndarray, np.ndarray, dict[str, Any]]


class AsyncWorlds:
    """The requests in flight of one vector env and the replies not yet returned.

    A request goes through the process's shared region (the fast lane) when
    it has one and no other request of the lane is unread; else as msgpack.

    Args:
        session: the sims and their connections.
        slices: ``(first, end)`` world indices of each process.
        num_envs: N.
        lanes: the sims' shared regions (None: msgpack only).
    """

    def __init__(
        self, session: SimSession, slices: Sequence[tuple[int, int]], num_envs: int, lanes: SharedLanes | None = None
    ) -> None:
        self.session = session
        self.lanes = lanes
        self.slices = list(slices)
        self._owner = np.repeat(np.arange(len(self.slices)), [hi - lo for lo, hi in self.slices])
        #: Worlds sent and not yet returned by :meth:`recv`.
        self.in_flight = np.zeros(num_envs, dtype=np.bool_)
        #: How many worlds :attr:`in_flight` marks (read on every step: no numpy call).
        self._in_flight_count = 0
        self._queues: list[deque[tuple[int, np.ndarray, np.ndarray]]] = [deque() for _ in self.slices]
        self._ready: deque[Chunk] = deque()
        self._ready_count = 0

    @property
    def busy(self) -> bool:
        """Some world is in flight (sent, not yet received)."""
        return self._in_flight_count > 0

    def send(self, ids: np.ndarray, ops: np.ndarray, actions: Any) -> None:
        """Send ``actions[j]`` with op ``ops[j]`` to world ``ids[j]`` (distinct, none in flight)."""
        if self.in_flight[ids].any():
            busy = ids[self.in_flight[ids]][:8].tolist()
            raise StateError(f"worlds {busy} are in flight already: recv() them before sending to them again")
        owners = self._owner[ids]
        conns, lanes, handshakes = self.session.conns, self.lanes, self.session.handshakes
        ops_list = ops.tolist()
        for p in np.unique(owners).tolist():
            sel = np.flatnonzero(owners == p)
            lo = self.slices[p][0]
            picked = actions[sel] if isinstance(actions, np.ndarray) else [actions[j] for j in sel]
            worlds = ids[sel] - lo
            seq = None
            if lanes is not None:
                seq = lanes.post(p, conns[p], handshakes[p].offers("shared_batch"), ops[sel], picked, worlds)
            if seq is None:
                seq = conns[p].send(
                    "step_batch", ops=[ops_list[j] for j in sel], actions=picked, worlds=worlds.tolist()
                )
            self._queues[p].append((seq, ids[sel], ops[sel]))
        self.in_flight[ids] = True
        self._in_flight_count += len(ids)

    def recv(self, batch_size: int) -> list[Chunk]:
        """Chunks covering exactly ``batch_size`` worlds, the earliest replies first."""
        if batch_size > self._in_flight_count:  # received, not yet returned worlds count as in flight
            raise StateError(
                f"recv() needs {batch_size} worlds in flight or received, but only "
                f"{self._in_flight_count} are: send() actions for more worlds first"
            )
        try:
            self._wait_for(batch_size)
        except RemoteEnvError:
            self.abandon()
            raise
        out: list[Chunk] = []
        need = batch_size
        while need:
            ids, ops, reply = self._ready.popleft()
            if len(ids) > need:
                first, rest = split_reply(reply, need)
                self._ready.appendleft((ids[need:], ops[need:], rest))
                ids, ops, reply = ids[:need], ops[:need], first
            out.append((ids, ops, reply))
            need -= len(ids)
            self._ready_count -= len(ids)
            self.in_flight[ids] = False
            self._in_flight_count -= len(ids)
        return out

    def abandon(self) -> None:
        """Forget every request in flight and every reply not yet returned (after a
        failure; replies that come later are stale and dropped)."""
        for p, queue in enumerate(self._queues):
            if queue and self.lanes is not None:
                self.lanes.forget(p)
            queue.clear()
        self._ready.clear()
        self._ready_count = 0
        self.in_flight[:] = False
        self._in_flight_count = 0

    # ------------------------------------------------------------ waiting

    def _wait_for(self, count: int) -> None:
        timeout = self.session.timeout_for("step_batch")
        deadline = None if timeout is None else time.monotonic() + timeout
        conns = self.session.conns
        while self._ready_count < count:
            waiting = [p for p, q in enumerate(self._queues) if q]
            poller = zmq.Poller()
            unpolled = []
            for p in waiting:
                pollable = conns[p].pollable
                if pollable is None:
                    unpolled.append(p)
                else:
                    poller.register(pollable, zmq.POLLIN)
            took = any([self._take(p) for p in waiting])
            if not took:
                # Before blocking, the sims must know to send a frame for replies they put in a region.
                blocking = not unpolled and all([getattr(conns[p], "will_block", _yes)() for p in waiting])
                try:
                    events = poller.poll(int(LIVENESS_CHECK_S * 1000) if blocking else 0)
                finally:
                    for p in waiting:
                        getattr(conns[p], "woke", _nothing)()
                if blocking and not events:
                    for p in waiting:
                        conns[p].check_alive("'step_batch'")
            # Checked on every round, whatever arrived: stale frames never extend it.
            if self._ready_count < count and deadline is not None and time.monotonic() > deadline:
                p = waiting[0]
                why = conns[p].why_silent() or (
                    "the process is alive but stuck or overloaded. Raise the vector env's timeout= "
                    "or check the scene code"
                )
                raise RemoteEnvTimeout(
                    f"sim instance {p} at {conns[p].endpoint} did not answer 'step_batch' within {timeout:g} s; {why}.",
                    kind="timeout",
                    instance=p,
                )

    def _take(self, p: int) -> bool:
        """Move every reply process ``p`` has sent into the ready chunks; True if any came."""
        queue, conn, took = self._queues[p], self.session.conns[p], False
        while queue:
            seq, ids, ops = queue[0]
            reply = conn.try_receive(seq, "'step_batch'")
            if reply is None:
                break
            checks = self.session.checks
            if self.lanes is not None:
                self.lanes.vouch(p, seq, reply)
            if checks is not None and reply.get("region") is not True:
                checks.batch(conn, "step_batch", reply, len(ids), shared=reply.get("shared") is True)
            if self.lanes is not None:
                # A shared reply's arrays come from the region; a region reply is copied out of it
                # (the next request to this process may use the region before recv() returns it).
                taken = self.lanes.take(p, conn, seq, reply, len(ids))
                reply = taken.as_reply() if isinstance(taken, RegionReply) else taken
            queue.popleft()
            self._ready.append((ids, ops, reply))
            self._ready_count += len(ids)
            took = True
        return took


def _yes() -> bool:
    return True


def _nothing() -> None:
    pass


def split_reply(reply: dict[str, Any], cut: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """A ``step_batch`` reply of ``n`` request positions as two: positions
    ``0 .. cut-1`` and ``cut .. n-1`` (the second's positions renumbered from
    0), each ``final`` entry with its ``final_types`` entry."""
    info = reply["info"]
    if "columns" in info:
        head_info = {"columns": {k: [v[:cut], m[:cut]] for k, (v, m) in info["columns"].items()}}
        tail_info = {"columns": {k: [v[cut:], m[cut:]] for k, (v, m) in info["columns"].items()}}
    else:
        head_info, tail_info = {"maps": info["maps"][:cut]}, {"maps": info["maps"][cut:]}
    head_final: list[Any] = []
    tail_final: list[Any] = []
    head: dict[str, Any] = {"info": head_info, "final": head_final}
    tail: dict[str, Any] = {"info": tail_info, "final": tail_final}
    for key in ("obs", "reward", "terminated", "truncated"):
        head[key], tail[key] = reply[key][:cut], reply[key][cut:]
    given = reply.get("final_types")
    typed = isinstance(given, list) and len(given) == len(reply["final"])
    types: list[Any] = list(given) if isinstance(given, list) and typed else [None] * len(reply["final"])
    head_types: list[Any] = []
    tail_types: list[Any] = []
    for k, (j, fobs, finfo) in enumerate(reply["final"]):
        if j < cut:
            head_final.append([j, fobs, finfo])
            head_types.append(types[k])
        else:
            tail_final.append([j - cut, fobs, finfo])
            tail_types.append(types[k])
    if typed:
        head["final_types"], tail["final_types"] = head_types, tail_types
    return head, tail


def assemble_chunks(
    chunks: Sequence[Chunk], obs_batch: ObsBatch, add_info: AddInfo
) -> tuple[np.ndarray, np.ndarray, Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """``(ids, ops, obs, rewards, terminated, truncated, infos)`` of the worlds of
    ``chunks`` in their order: what :func:`~remoteenv.agent.vector.vector_results.assemble`
    makes of one reply per process, for a batch of ``obs_batch.num_envs`` worlds
    (``infos`` in Gymnasium's layout for that batch, plus ``env_id``)."""
    results: dict[int, dict[str, Any]] = {}
    slices: list[tuple[int, int]] = []
    lo = 0
    for c, (ids, _, reply) in enumerate(chunks):
        results[c] = reply
        slices.append((lo, lo + len(ids)))
        lo += len(ids)
    obs, rewards, terminated, truncated, infos = assemble(results, slices, obs_batch, add_info)
    ids = np.concatenate([chunk[0] for chunk in chunks])
    ops = np.concatenate([chunk[1] for chunk in chunks])
    infos["env_id"] = ids
    return ids, ops, obs, rewards, terminated, truncated, infos


__all__ = ["AsyncWorlds", "Chunk", "assemble_chunks", "split_reply"]
