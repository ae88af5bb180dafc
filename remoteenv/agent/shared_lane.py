"""The agent's ends of its local sims' shared-memory regions (``shared_batch``).

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`, lock-step
batched steps). For each sim process reached over its local pipe that offers
``shared_batch``, the first vector step asks for the region and maps it
(:mod:`remoteenv.wire.shared_batch`); from then on a vector step whose
actions are one array of the region's dtype and shape writes them there and
sends ``step_batch`` with ``"shared": true``, and a reply marked shared has
its arrays read back from the region. Anything else (a sim that does not
offer it, a region that cannot be mapped, other actions) takes the usual
msgpack path, with the same results.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.sim_connection import SimConnection
from remoteenv.wire.errors import ProtocolError
from remoteenv.wire.shared_batch import SharedArrays, SharedLayout, map_region


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
    except (RemoteEnvError, ProtocolError, OSError):
        return None  # the step's own request reports a sim that is gone


class SharedLanes:
    """The mapped regions of a vector env's sim processes, by process index;
    attached on first use and again after a process was replaced."""

    def __init__(self) -> None:
        self._lanes: dict[int, tuple[SimConnection, SharedArrays | None]] = {}
        #: The processes whose last actions went through their region.
        self._written: set[int] = set()

    def get(self, p: int, conn: SimConnection, offered: bool) -> SharedArrays | None:
        """Process ``p``'s region (``conn`` is its connection; ``offered``: its
        handshake lists ``shared_batch``), or None."""
        known = self._lanes.get(p)
        if known is not None and known[0] is conn:
            return known[1]
        if known is not None and known[1] is not None:
            known[1].close()
        arrays = attach(conn) if offered and conn.waits_in_turn else None
        self._lanes[p] = (conn, arrays)
        return arrays

    def put_actions(self, p: int, conn: SimConnection, offered: bool, actions: Any) -> bool:
        """Write ``actions`` (one array for positions ``0 .. n-1``) into process
        ``p``'s region; False (nothing written) if it has none or they do not fit."""
        self._written.discard(p)
        arrays = self.get(p, conn, offered)
        if arrays is None or not isinstance(actions, np.ndarray):
            return False
        n = len(actions)
        block = arrays.actions
        if actions.dtype != block.dtype or actions.shape[1:] != block.shape[1:] or not 0 < n <= len(block):
            return False
        block[:n] = actions
        self._written.add(p)
        return True

    def fill(self, p: int, reply: dict[str, Any], n: int) -> None:
        """Put the arrays of a shared reply for ``n`` positions into ``reply``
        (fresh copies, as a decoded reply would hold them). A shared reply to
        actions that did not go through the region is a ``protocol`` error."""
        arrays = self._lanes[p][1] if p in self._written else None
        if arrays is None:
            raise RemoteEnvError(
                f"sim instance {p} answered a step_batch sent over the wire as if it used "
                "the shared region; its reply is off the protocol",
                kind="protocol",
                instance=p,
            )
        reply["obs"] = arrays.obs[:n].copy()
        reply["reward"] = arrays.reward[:n].copy()
        reply["terminated"] = arrays.terminated[:n].copy()
        reply["truncated"] = arrays.truncated[:n].copy()

    def close(self) -> None:
        for _, arrays in self._lanes.values():
            if arrays is not None:
                arrays.close()
        self._lanes.clear()


__all__ = ["SharedLanes", "attach"]
