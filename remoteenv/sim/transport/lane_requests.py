"""The requests side of a sim's shared region: what the agent posted, taken for serving.

Runs in the sim process (lock step).
:class:`~remoteenv.sim.transport.shared_lane_server.SharedLane` is a
:class:`LaneRequests`: this part watches the doorbell's request words for
the pipe channel's waits, takes a request's ops, worlds and actions out of
the region's blocks (copies; the ops checked, the actions for the caller to
check), and notices a header tampered with (then the region is dropped, see
:mod:`remoteenv.wire.shared_memory.doorbell`). The replies are
:class:`~remoteenv.sim.transport.shared_lane_server.SharedLane`'s.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from remoteenv.sim.transport.channels import Channel, PipeChannel
from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.protocol import OP_STEP, OPS
from remoteenv.wire.shared_memory.doorbell import Doorbell
from remoteenv.wire.shared_memory.shared_batch import SharedArrays
from remoteenv.wire.wire_errors import PROTOCOL, STATE

_LAST_OP = max(OPS)


class LaneRequests:
    """The region's requests, once the region exists (:attr:`doorbell` set by its owner)."""

    def __init__(self) -> None:
        self._arrays: SharedArrays | None = None
        #: The fast lane's doorbell (once the region exists).
        self.doorbell: Doorbell | None = None
        #: ``seq`` of the last request taken from the region.
        self.served = 0
        #: The agent's think time before that request (seconds, 0: not told; the doorbell's ``AGENT_THINK_US``).
        self.agent_think_s = 0.0
        #: Why the region is no longer used (its header was tampered with), or None.
        self.tampered: str | None = None
        #: The pipe the last region request came on (heads-ups go there).
        self._channel: PipeChannel | None = None
        #: The ops block of a plain step of every world, as bytes (made on first use).
        self._plain_ops: bytes | None = None

    # ------------------------------------------------------------ the pipe channel's watch

    def posted(self) -> int:
        """``seq`` of a request posted in the region and not yet served (0: none)."""
        return 0 if self.doorbell is None else self.doorbell.posted(self.served)

    def agent_away(self) -> bool:
        """Whether the agent said its caller began a long think after the last
        reply (the doorbell's ``AGENT_AWAY``): a hot wait for its next request stops."""
        doorbell = self.doorbell
        return doorbell is not None and doorbell.agent_away()

    def settle(self) -> int:
        """The sim is about to block: stop watching the region (a request posted
        from now on comes with its frame); a request that came meanwhile (0: none)."""
        if self.doorbell is None or self._found_tampered():
            return 0
        return self.doorbell.sim_sleeps(self.served)

    def _found_tampered(self) -> bool:
        """Whether the header is not what the two sides can have written: then
        the region is dropped (poisoned for the agent to see, see
        :mod:`remoteenv.wire.shared_memory.doorbell`) and every later step takes the pipe."""
        doorbell = self.doorbell
        if doorbell is None:
            return self.tampered is not None
        why = doorbell.sim_tampered(self.served)
        if why is None:
            return False
        doorbell.poison()
        self.doorbell = None
        self.tampered = why
        print(
            f"remoteenv sim: the shared-memory region was tampered with ({why}); it is no longer used, "
            "batched steps take the pipe",
            file=sys.stderr,
            flush=True,
        )
        return True

    def _refuse_tampered(self) -> None:
        if self._found_tampered():
            raise RequestError(STATE, f"the shared-memory region was tampered with ({self.tampered}) and is not used")

    # ------------------------------------------------------------ requests

    def actions(self, n: int, channel: Channel | None) -> np.ndarray:
        """A copy of the actions of request positions ``0 .. n-1`` (checked by the caller)."""
        arrays = self._arrays
        if arrays is None or not isinstance(channel, PipeChannel):
            raise RequestError(STATE, "a 'shared' step_batch needs the region of shared_batch, over the local pipe")
        self._refuse_tampered()
        if not 0 < n <= len(arrays.actions):
            raise RequestError(PROTOCOL, f"a 'shared' step_batch covers 1..{len(arrays.actions)} worlds, got {n}")
        return arrays.actions[:n].copy()

    def take(self, seq: int, channel: Channel | None) -> tuple[list[int], list[int] | None, np.ndarray] | None:
        """The request ``seq`` posted in the region: ``(ops, worlds, actions)``
        for its ``n`` positions (copies; ops checked, worlds as listed or None
        for ``0 .. n-1``, actions for the caller to check), or None if it was
        served already (its frame came after the watch found it: nothing to answer)."""
        self._refuse_tampered()
        arrays, doorbell = self._arrays, self.doorbell
        if arrays is None or doorbell is None or not isinstance(channel, PipeChannel):
            raise RequestError(STATE, "a region step_batch needs the region of shared_batch, over the local pipe")
        if seq <= self.served:
            return None
        posted, n, named = doorbell.request()
        if posted != seq:
            raise RequestError(PROTOCOL, f"a region step_batch {seq}, but the region holds request {posted}")
        self._taken(seq, channel, doorbell)
        k = arrays.layout.worlds
        if not 0 < n <= k:
            raise RequestError(PROTOCOL, f"a region request covers 1..{k} worlds, got {n}")
        assert arrays.ops is not None and arrays.worlds is not None
        # A list of at most K Python ints is checked faster than numpy reduces its array.
        ops: list[int] = arrays.ops[:n].tolist()
        if min(ops) < 0 or max(ops) > _LAST_OP:
            raise RequestError(PROTOCOL, f"a region request's ops must be in {OPS}")
        worlds = arrays.worlds[:n].tolist() if named else None
        return ops, worlds, arrays.actions[:n].copy()

    def take_plain(self, seq: int, channel: Channel | None, check: Callable[[Any, int], Any]) -> np.ndarray | None:
        """Request ``seq``, taken as :meth:`take` takes it, if it is a plain step
        of every world: all ``K`` positions, no worlds named, every op
        ``OP_STEP``, a header untampered with, actions that ``check`` (the
        caller's action check, called as ``check(actions, K)``) accepts and
        returns as an array. Returns those checked actions; None, with nothing
        taken, for any other request (the usual way, :meth:`take`, then takes
        it and reports what is wrong with it)."""
        arrays, doorbell = self._arrays, self.doorbell
        if arrays is None or doorbell is None or seq <= self.served or not isinstance(channel, PipeChannel):
            return None
        posted, n, named = doorbell.request()
        k = arrays.layout.worlds
        if posted != seq or named or n != k or arrays.ops is None:
            return None
        plain = self._plain_ops
        if plain is None:
            plain = self._plain_ops = np.full(k, OP_STEP, dtype=arrays.ops.dtype).tobytes()
        if arrays.ops[:k].tobytes() != plain or doorbell.sim_tampered(self.served) is not None:
            return None
        try:
            checked = check(arrays.actions[:k].copy(), k)
        except Exception:  # refused: the usual way checks again and says why
            return None
        if not isinstance(checked, np.ndarray):
            return None
        self._taken(seq, channel, doorbell)
        return checked

    def _taken(self, seq: int, channel: PipeChannel, doorbell: Doorbell) -> None:
        """Request ``seq`` has been taken from the region, from ``channel``: served,
        heads-ups go there, and its agent's think time is read."""
        self.served = seq
        self._channel = channel
        self.agent_think_s = doorbell.agent_think_s()


__all__ = ["LaneRequests"]
