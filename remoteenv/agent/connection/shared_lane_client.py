"""The agent's ends of its local sims' shared-memory regions (``shared_batch``).

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`, lock-step
batched steps). For each sim process reached over its local pipe that offers
``shared_batch``, the first vector step asks for the region and maps it
(:mod:`remoteenv.wire.shared_memory.shared_batch`); from then on a vector step whose
actions are one array of the region's dtype and shape writes them there and
sends ``step_batch`` with ``"shared": true``, and a reply marked shared has
its arrays read back from the region. Anything else (a sim that does not
offer it, a region that cannot be mapped, other actions) takes the usual
msgpack path, with the same results.

A region is used only when it is safe to map: sealed against shrinking (a
truncated mapping would kill this process with ``SIGBUS``, see
:func:`~remoteenv.wire.shared_memory.shared_batch.map_region`) and laid out for the env's
observation space. Otherwise the lane warns once (``RuntimeWarning``) and
takes the msgpack path. Flags read from the region are taken as bytes (any
nonzero byte is true), so they are proper bools whatever the sim wrote.

With the fast lane (:mod:`remoteenv.wire.shared_memory.doorbell`) a whole ``step_batch``
goes through the region: ops, worlds and actions in, and, for a plain step,
observations, rewards, flags and the infos as typed columns out, without a
frame while both sides are awake. The sim announces the columns (keys,
dtypes) in a pipe reply before it first uses them; the agent checks the
announcement once (:meth:`remoteenv.agent.connection.reply_checks.ReplyChecks.info_layout`)
and then takes a region reply only for the request it names and in the
layout announced.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.agent.connection.reply_checks import ReplyChecks
from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire.codec.arrays import wire_dtype
from remoteenv.wire.protocol import OP_RESET, OP_STEP_RESET
from remoteenv.wire.shared_memory.doorbell import REP_INFO, REP_SEQ, Doorbell
from remoteenv.wire.shared_memory.shared_batch import SharedArrays, SharedLayout, UnsealedRegion, map_region
from remoteenv.wire.wire_errors import ProtocolError


def attach(conn: SimConnection) -> SharedArrays | None:
    """Ask the sim behind ``conn`` for its region and map it; None if it cannot be had."""
    pid = getattr(conn, "pid", None)
    if pid is None:
        return None
    try:
        reply = conn.request("shared_batch")
        fd = reply.get("fd")
        if reply.get("pid") != pid or type(fd) is not int or fd < 0:
            return None
        return map_region(f"/proc/{pid}/fd/{fd}", SharedLayout.from_wire(reply.get("layout")))
    except UnsealedRegion as exc:
        _fall_back(conn, f"{exc}: a sim could end this process with SIGBUS by truncating it")
        return None
    except (RemoteEnvError, ProtocolError, OSError):
        return None  # the step's own request reports a sim that is gone


def _fall_back(conn: SimConnection, why: str) -> None:
    warnings.warn(
        f"sim instance {conn.instance}'s shared-memory region is not used ({why}); its batched steps "
        "take the msgpack path over the pipe (the same results, somewhat slower)",
        RuntimeWarning,
        stacklevel=2,
    )


class RegionReply:
    """A ``step_batch`` reply the sim wrote into a process's region (the fast
    lane): views of its first ``n`` rows and of its info columns, as announced
    (``(key, "_" + key, dtype, values)``). Read it (see
    :func:`~remoteenv.agent.vector.vector_results.assemble`) before the next request
    to that process; :meth:`as_reply` copies it into the usual reply form."""

    __slots__ = ("columns", "n", "obs", "reward", "terminated", "truncated", "version")

    def __init__(self, arrays: SharedArrays, version: int, columns: list[tuple[str, np.dtype, bool]], n: int) -> None:
        self.n, self.version = n, version
        self.obs = arrays.obs[:n]
        self.reward = arrays.reward[:n]
        # The flags as bytes: any nonzero byte is true (numpy keeps a byte of 2 as a "true" that ~ does not negate).
        self.terminated = arrays.terminated[:n].view(np.uint8)
        self.truncated = arrays.truncated[:n].view(np.uint8)
        self.columns = [(key, f"_{key}", dt, arrays.info_column(c, dt)[:n]) for c, (key, dt, _) in enumerate(columns)]

    def as_reply(self) -> dict[str, Any]:
        """The reply in ``step_batch`` form (fresh copies)."""
        present = np.ones(self.n, dtype=np.bool_)
        return {
            "obs": self.obs.copy(),
            "reward": self.reward.copy(),
            "terminated": self.terminated != 0,
            "truncated": self.truncated != 0,
            "info": {"columns": {key: [values.copy(), present] for key, _, _, values in self.columns}},
            "final": [],
        }


class SharedLanes:
    """The mapped regions of a vector env's sim processes, by process index;
    attached on first use and again after a process was replaced.

    A region with the fast lane's blocks (:mod:`remoteenv.wire.shared_memory.doorbell`) takes
    whole requests (:meth:`post`), one at a time per process; a region without
    them takes actions for ``"shared": true`` requests (:meth:`put_actions`).

    Args:
        observation_space: the env's observation space; a region laid out for
            another is not used (None: not checked).
        checks: the env's reply checks (for the sims' announcements of info columns).
    """

    def __init__(self, observation_space: spaces.Space | None = None, checks: ReplyChecks | None = None) -> None:
        self._obs_layout: tuple[str, tuple[int, ...]] | None = None
        if isinstance(observation_space, spaces.Box):
            try:
                self._obs_layout = (wire_dtype(np.dtype(observation_space.dtype)), tuple(observation_space.shape))
            except TypeError:  # a dtype the wire does not carry: no region fits it
                self._obs_layout = ("", ())
        elif observation_space is not None:
            self._obs_layout = ("", ())
        self._checks = checks
        self._lanes: dict[int, tuple[SimConnection, SharedArrays | None]] = {}
        self._bells: dict[int, Doorbell] = {}
        #: Per process, the announced info columns: version and ``(key, dtype, python)``.
        self._infos: dict[int, tuple[int, list[tuple[str, np.dtype, bool]]]] = {}
        #: Per process, the views of its last region reply (reused while ``n`` and the layout stay).
        self._views: dict[int, RegionReply] = {}
        #: Per process, the views of its last request's blocks (actions, ops, worlds of ``n`` rows) and
        #: the read-only ops array last written there (not written again: only the agent writes that block).
        self._blocks: dict[int, _RequestBlocks] = {}
        #: Per process, the request whose actions are in its region and whose reply has not been read.
        self._pending: dict[int, int] = {}
        #: The processes whose last actions went through their region (``"shared": true`` requests).
        self._written: set[int] = set()
        #: Changes whenever what is kept of a region changes (a :class:`LaneReady` of an older one is stale).
        self.generation = 0

    def get(self, p: int, conn: SimConnection, offered: bool) -> SharedArrays | None:
        """Process ``p``'s region (``conn`` is its connection; ``offered``: its
        handshake lists ``shared_batch``), or None."""
        known = self._lanes.get(p)
        if known is not None and known[0] is conn:
            return known[1]
        self._drop(p)
        self._pending.pop(p, None)
        arrays = attach(conn) if offered and conn.waits_in_turn else None
        if arrays is not None and self._obs_layout is not None:
            layout = arrays.layout
            if (layout.obs_dtype, layout.obs_shape) != self._obs_layout:
                arrays.close()
                arrays = None
                _fall_back(
                    conn, f"laid out for observations {layout.obs_dtype} {list(layout.obs_shape)}, not the env's"
                )
        if arrays is not None and arrays.header is not None and hasattr(conn, "post"):
            self._bells[p] = Doorbell(arrays.header)
        self._lanes[p] = (conn, arrays)
        return arrays

    # ------------------------------------------------------------ requests

    def post(
        self,
        p: int,
        conn: SimConnection,
        offered: bool,
        ops: np.ndarray,
        actions: Any,
        worlds: np.ndarray | None = None,
        think_s: float = 0.0,
    ) -> int | None:
        """Post a ``step_batch`` in process ``p``'s region: ``ops`` and ``actions``
        of positions ``0 .. n-1`` (and the ``worlds`` they address, if given);
        ``think_s``: the agent's think time before it (seconds, 0: not told).
        Returns its ``seq``, or None (nothing written: no lane, a request of the
        lane still unread, or actions that are not one array of its dtype)."""
        if p in self._pending:
            return None
        arrays = self.get(p, conn, offered)
        bell = self._bells.get(p)
        if arrays is None or bell is None or not _fits(arrays.actions, actions) or self._tampered(p, conn):
            return None
        n = len(actions)
        blocks = self._blocks.get(p)
        if blocks is None or blocks.n != n:
            blocks = self._blocks[p] = _RequestBlocks(arrays, n)
        blocks.actions[...] = actions
        if ops is not blocks.ops_written:
            self._write_ops(blocks, ops)
        if worlds is not None:
            blocks.worlds[...] = worlds
        seq: int = conn.post(bell, n, worlds is not None, think_s, blocks.plain)  # type: ignore[attr-defined]
        self._pending[p] = seq
        return seq

    def away(self) -> None:
        """Tell every sim whose region has no request in flight that the caller
        began a long think (the doorbell's ``AGENT_AWAY``): its hot wait stops."""
        for p, bell in self._bells.items():
            if p not in self._pending:
                bell.away()

    def put_actions(self, p: int, conn: SimConnection, offered: bool, actions: Any) -> bool:
        """Write ``actions`` (one array for positions ``0 .. n-1``) into process
        ``p``'s region for a ``"shared": true`` request; False (nothing written)
        if it has none, its lane is in use or they do not fit."""
        self._written.discard(p)
        arrays = self.get(p, conn, offered)
        if arrays is None or p in self._pending or not _fits(arrays.actions, actions) or self._tampered(p, conn):
            return False
        arrays.actions[: len(actions)] = actions
        self._written.add(p)
        return True

    # ------------------------------------------------------------ replies

    def vouch(self, p: int, seq: int, reply: dict[str, Any]) -> None:
        """Refuse (a ``protocol`` error) a reply of process ``p`` to request ``seq``
        that says it used the region when that request did not go through it."""
        if reply.get("region") is True and self._pending.get(p) != seq:
            self._off_protocol(p, "answered in the shared region a request that was not posted there")
        if reply.get("shared") is True and self._pending.get(p) != seq and p not in self._written:
            self._off_protocol(p, "answered a step_batch sent over the wire as if it used the shared region")

    def take(
        self, p: int, conn: SimConnection, seq: int, reply: dict[str, Any], n: int
    ) -> dict[str, Any] | RegionReply:
        """The reply (vouched for and checked) to process ``p``'s request ``seq``
        for ``n`` positions: a :class:`RegionReply` when the sim answered in the
        region, else ``reply`` with the arrays of a shared reply filled in
        (learning the info columns it announces). A region reply of another
        request or layout than the region holds is a ``protocol`` error."""
        self.vouch(p, seq, reply)
        if self._pending.get(p) == seq:
            del self._pending[p]
        if reply.get("region") is True:
            return self._region_reply(p, seq, n)
        if reply.get("shared") is True:
            self.fill(p, reply, n)
            layout = reply.get("info_layout")
            if layout is not None:
                self._learn(p, conn, layout)
        return reply

    def forget(self, p: int) -> None:
        """Process ``p``'s request in flight will not be read (a failure)."""
        self._pending.pop(p, None)

    def fill(self, p: int, reply: dict[str, Any], n: int) -> None:
        """Put the arrays of a shared reply for ``n`` positions into ``reply``
        (fresh copies, as a decoded reply would hold them)."""
        arrays = self._lanes[p][1] if p in self._lanes else None
        if arrays is None:
            self._off_protocol(p, "answered as if it used the shared region, which it has not")
        assert arrays is not None
        reply["obs"] = arrays.obs[:n].copy()
        reply["reward"] = arrays.reward[:n].copy()
        # Bytes the sim wrote, as proper bools (numpy keeps a byte of 2 as a "true" that ~ does not negate).
        reply["terminated"] = arrays.terminated[:n].view(np.uint8) != 0
        reply["truncated"] = arrays.truncated[:n].view(np.uint8) != 0

    def _region_reply(self, p: int, seq: int, n: int) -> RegionReply:
        arrays, bell, infos = self._lanes[p][1] if p in self._lanes else None, self._bells.get(p), self._infos.get(p)
        if arrays is None or bell is None:
            self._off_protocol(p, "answered in the shared region a request that was not posted there")
        assert arrays is not None and bell is not None
        version = infos[0] if infos is not None else 0
        if bell.word(REP_SEQ) != seq or bell.word(REP_INFO) != version or infos is None:
            self._off_protocol(
                p, f"said its region holds the reply to request {seq} in info layout {version}, and it does not"
            )
        assert infos is not None
        view = self._views.get(p)
        if view is None or view.n != n or view.version != version:
            view = self._views[p] = RegionReply(arrays, version, infos[1], n)
            self.generation += 1
        return view

    def ready(self, p: int, conn: SimConnection, n: int, ops: np.ndarray) -> LaneReady | None:
        """What a plain step of ``n`` positions of process ``p`` (connection
        ``conn``) with the read-only ``ops`` needs to go through its region with
        no look-up on the way, once such a step went the usual way (its request
        blocks hold ``ops``, its reply views and info layout are known); else None."""
        known, bell, infos = self._lanes.get(p), self._bells.get(p), self._infos.get(p)
        blocks, view = self._blocks.get(p), self._views.get(p)
        if known is None or known[0] is not conn or bell is None or infos is None or blocks is None or view is None:
            return None
        if blocks.n != n or view.n != n or view.version != infos[0] or p in self._pending:
            return None
        if blocks.ops_written is not ops:  # e.g. the step after a reset: its plain plan written again
            self._write_ops(blocks, ops)
        if not blocks.plain:
            return None
        return LaneReady(self, p, conn, bell, blocks.actions, ops, view)

    def _write_ops(self, blocks: _RequestBlocks, ops: np.ndarray) -> None:
        """Write ``ops`` into the request blocks (a request's other blocks come with it)."""
        self.generation += 1
        blocks.ops[...] = ops
        blocks.ops_written = None if ops.flags.writeable else ops
        blocks.plain = _plain(ops)

    def _tampered(self, p: int, conn: SimConnection) -> bool:
        """Whether process ``p``'s region header is not what the two sides can
        have written (:meth:`Doorbell.agent_tampered`): then the region is
        dropped with a warning and its steps take the msgpack path for good."""
        bell = self._bells.get(p)
        why = None if bell is None else bell.agent_tampered()
        if why is None:
            return False
        self._drop(p)
        self._lanes[p] = (conn, None)
        _fall_back(conn, f"it was tampered with: {why}")
        return True

    def _drop(self, p: int) -> None:
        """Unmap process ``p``'s region and forget what was kept of it (its request in flight aside)."""
        known = self._lanes.get(p)
        if known is not None and known[1] is not None:
            known[1].close()
        self._bells.pop(p, None)
        self._infos.pop(p, None)
        self._views.pop(p, None)
        self._blocks.pop(p, None)
        self.generation += 1

    def _learn(self, p: int, conn: SimConnection, layout: Any) -> None:
        arrays = self._lanes[p][1]
        if arrays is None or arrays.info is None or self._checks is None:
            return
        known = self._infos.get(p)
        self.generation += 1
        self._infos[p] = self._checks.info_layout(conn, layout, arrays.layout.info_columns, known[0] if known else 0)

    @staticmethod
    def _off_protocol(p: int, what: str) -> None:
        raise RemoteEnvError(f"sim instance {p} {what}; its reply is off the protocol", kind="protocol", instance=p)

    def close(self) -> None:
        for _, arrays in self._lanes.values():
            if arrays is not None:
                arrays.close()
        self._lanes.clear()
        self._bells.clear()
        self._infos.clear()
        self._views.clear()
        self._blocks.clear()
        self._pending.clear()
        self.generation += 1


class LaneReady:
    """A process's region as :meth:`SharedLanes.ready` found it ready for plain
    steps: valid while :attr:`SharedLanes.generation` stays :attr:`generation`."""

    __slots__ = ("actions", "bell", "conn", "generation", "ops", "p", "pending", "view")

    def __init__(
        self,
        lanes: SharedLanes,
        p: int,
        conn: SimConnection,
        bell: Doorbell,
        actions: np.ndarray,
        ops: np.ndarray,
        view: RegionReply,
    ) -> None:
        self.generation = lanes.generation
        #: The lanes' requests in flight by process (a request posted here is entered there).
        self.pending = lanes._pending
        self.p, self.conn, self.bell, self.actions, self.ops, self.view = p, conn, bell, actions, ops, view


class _RequestBlocks:
    """Views of rows ``0 .. n-1`` of a region's request blocks, and the read-only
    ops array written there last (None: write the ops again)."""

    __slots__ = ("actions", "n", "ops", "ops_written", "plain", "worlds")

    def __init__(self, arrays: SharedArrays, n: int) -> None:
        assert arrays.ops is not None and arrays.worlds is not None
        self.n = n
        self.actions, self.ops, self.worlds = arrays.actions[:n], arrays.ops[:n], arrays.worlds[:n]
        self.ops_written: np.ndarray | None = None
        #: The ops written last reset no world first (a plain step, see :func:`_plain`).
        self.plain = False


def _plain(ops: np.ndarray) -> bool:
    """Whether a request of ``ops`` is a plain step: no position resets before it
    steps (its reply comes in the region unless an episode ends within it)."""
    listed = ops.tolist()
    return OP_RESET not in listed and OP_STEP_RESET not in listed


def _fits(block: np.ndarray, actions: Any) -> bool:
    """Whether ``actions`` is one array of ``block``'s dtype and row shape, for 1 .. K positions."""
    return (
        isinstance(actions, np.ndarray)
        and actions.dtype == block.dtype
        and actions.shape[1:] == block.shape[1:]
        and 0 < len(actions) <= len(block)
    )


__all__ = ["LaneReady", "RegionReply", "SharedLanes", "attach"]
