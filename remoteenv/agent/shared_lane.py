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

A region is used only when it is safe to map: sealed against shrinking (a
truncated mapping would kill this process with ``SIGBUS``, see
:func:`~remoteenv.wire.shared_batch.map_region`) and laid out for the env's
observation space. Otherwise the lane warns once (``RuntimeWarning``) and
takes the msgpack path. Flags read from the region are taken as bytes (any
nonzero byte is true), so they are proper bools whatever the sim wrote.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.sim_connection import SimConnection
from remoteenv.wire.arrays import wire_dtype
from remoteenv.wire.errors import ProtocolError
from remoteenv.wire.shared_batch import SharedArrays, SharedLayout, UnsealedRegion, map_region


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


class SharedLanes:
    """The mapped regions of a vector env's sim processes, by process index;
    attached on first use and again after a process was replaced.

    Args:
        observation_space: the env's observation space; a region laid out for
            another is not used (None: not checked).
    """

    def __init__(self, observation_space: spaces.Space | None = None) -> None:
        self._obs_layout: tuple[str, tuple[int, ...]] | None = None
        if isinstance(observation_space, spaces.Box):
            try:
                self._obs_layout = (wire_dtype(np.dtype(observation_space.dtype)), tuple(observation_space.shape))
            except TypeError:  # a dtype the wire does not carry: no region fits it
                self._obs_layout = ("", ())
        elif observation_space is not None:
            self._obs_layout = ("", ())
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
        if arrays is not None and self._obs_layout is not None:
            layout = arrays.layout
            if (layout.obs_dtype, layout.obs_shape) != self._obs_layout:
                arrays.close()
                arrays = None
                _fall_back(
                    conn, f"laid out for observations {layout.obs_dtype} {list(layout.obs_shape)}, not the env's"
                )
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
        # Bytes the sim wrote, as proper bools (numpy keeps a byte of 2 as a "true" that ~ does not negate).
        reply["terminated"] = arrays.terminated[:n].view(np.uint8) != 0
        reply["truncated"] = arrays.truncated[:n].view(np.uint8) != 0

    def close(self) -> None:
        for _, arrays in self._lanes.values():
            if arrays is not None:
                arrays.close()
        self._lanes.clear()


__all__ = ["SharedLanes", "attach"]
