"""The sim's end of the shared-memory region of the local pipe (``shared_batch``).

Runs in the sim process (lock-step). The launching agent asks for the region
once with ``shared_batch``; after that its ``step_batch`` requests may carry
``"shared": true`` instead of ``actions`` (read from the region), and a
plain step (every world stepped, none reset) answers with its arrays in the
region. The region also holds the fast lane (:mod:`remoteenv.wire.shared_memory.doorbell`):
a request posted in the region (ops, worlds and actions, announced by its
sequence word, or by a ``{"cmd": "step_batch", "region": true}`` frame when
this sim sleeps) is served like any ``step_batch``; its reply goes into the region with its infos as typed
columns, and no frame at all while the agent watches the region. Layout and
rules: :mod:`remoteenv.wire.shared_memory.shared_batch`; wire form: :mod:`remoteenv.wire.protocol`.
Only the launching agent's pipe may use it: a ZeroMQ client gets a ``state`` error.
"""

from __future__ import annotations

import dataclasses
import os
import time
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim.scene.batch_result import BatchResult, widened
from remoteenv.sim.transport.channels import Channel, PipeChannel
from remoteenv.sim.transport.checks import RequestError
from remoteenv.sim.transport.lane_requests import LaneRequests
from remoteenv.wire.codec.arrays import wire_dtype
from remoteenv.wire.messages.batch_encoding import COLUMN_KINDS
from remoteenv.wire.protocol import reply_soon
from remoteenv.wire.shared_memory.doorbell import Doorbell
from remoteenv.wire.shared_memory.shared_batch import SharedLayout, create_region
from remoteenv.wire.wire_errors import STATE

#: Info columns the region of a sim holds for the fast lane.
INFO_COLUMNS = 16
#: A sim whose last region answer came this long (seconds) or longer after its
#: physics sends no heads-up: the agent would wait hot through the rest of the tick.
HEADS_UP_TAIL_S = 0.5e-3


def layout_for(action_space: spaces.Space, obs_space: spaces.Space, worlds: int) -> SharedLayout | None:
    """The region's layout for ``worlds`` worlds of these spaces, or None when
    they do not fit one (actions Box or Discrete, observations Box)."""
    if not isinstance(obs_space, spaces.Box):
        return None
    try:
        obs_dtype = wire_dtype(np.dtype(obs_space.dtype))
        if isinstance(action_space, spaces.Box):
            action: tuple[str, tuple[int, ...]] = (wire_dtype(np.dtype(action_space.dtype)), action_space.shape)
        elif isinstance(action_space, spaces.Discrete):
            action = ("<i8", ())
        else:
            return None
    except TypeError:  # a dtype the wire does not carry
        return None
    return SharedLayout(worlds, action[0], tuple(action[1]), obs_dtype, tuple(obs_space.shape))


class SharedLane(LaneRequests):
    """The region of one sim process's worlds, created on the agent's first ``shared_batch``:
    its requests as :class:`~remoteenv.sim.transport.lane_requests.LaneRequests` takes them, its replies.

    Args:
        action_space, obs_space: the worlds' spaces.
        worlds: how many worlds the process hosts.
    """

    def __init__(self, action_space: spaces.Space, obs_space: spaces.Space, worlds: int) -> None:
        base = layout_for(action_space, obs_space, worlds)
        self.layout = None if base is None else dataclasses.replace(base, info_columns=INFO_COLUMNS)
        super().__init__()
        self._fd: int | None = None
        self._info_version = 0
        self._info_signature: tuple[tuple[str, np.dtype, bool], ...] | None = None
        #: Views of rows ``0 .. n-1`` of the region's info columns, by column, dtype and ``n`` (made once).
        self._column_views: dict[tuple[int, np.dtype, int], np.ndarray] = {}
        #: Views of the region's obs, reward, terminated and truncated rows ``0 .. n-1``, by ``n`` (made once).
        self._row_views: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        #: When the physics of the request being served was done (perf_counter s; 0: not yet).
        self._physics_done = 0.0
        #: Seconds from the physics to the region answer, last time (0: not known).
        self._tail_s = 0.0

    @property
    def offered(self) -> bool:
        """Whether the spaces fit a region (else ``shared_batch`` is not advertised)."""
        return self.layout is not None

    def attach(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        """The ``shared_batch`` command: the region's pid, descriptor and layout."""
        if not isinstance(channel, PipeChannel) or self.layout is None:
            raise RequestError(STATE, "shared_batch is offered to the launching agent over its local pipe only")
        if self._arrays is None:
            self._fd, self._arrays = create_region(self.layout)
            assert self._arrays.header is not None
            self.doorbell = Doorbell(self._arrays.header)
        channel.lane = self  # its waits look at the doorbell too
        return {"pid": os.getpid(), "fd": self._fd, "layout": self.layout.to_wire()}

    # ------------------------------------------------------------ replies

    def physics_done(self, seq: int) -> None:
        """The physics of region request ``seq`` is done: send the agent the
        heads-up ``{"seq": seq, "soon": true}`` if it sleeps waiting for the
        reply and asked for one (:mod:`remoteenv.wire.shared_memory.doorbell`),
        unless this sim's last region answer came :data:`HEADS_UP_TAIL_S` or
        more after its physics (the agent would wait hot for long)."""
        self._physics_done = time.perf_counter()
        doorbell, channel = self.doorbell, self._channel
        if doorbell is None or channel is None or self._tail_s >= HEADS_UP_TAIL_S:
            return
        if doorbell.agent_wants_heads_up():
            channel.send(None, reply_soon(seq))

    def reply(self, batch: BatchResult, info: dict[str, Any]) -> dict[str, Any] | None:
        """Put a plain step's arrays in the region and return the reply's other
        fields; None if the obs batch does not fit the layout (then the caller
        answers the usual way)."""
        if self.tampered is not None or not self._put_arrays(batch):
            return None
        return {"shared": True, "info": info, "final": []}

    def answer(self, seq: int, batch: BatchResult) -> tuple[bool, dict[str, Any] | None]:
        """Answer region request ``seq``, a plain step, in the region if it fits:
        ``(True, None)`` answered, the agent watches; ``(True, {"region": True})``
        answered, wake the agent with that reply. Otherwise the caller replies on
        the pipe: ``(False, fields)`` with the arrays in the region (add the
        ``info``; a new ``info_layout`` is announced when the infos are columns
        the region can hold next time), ``(False, None)`` the usual way."""
        try:
            return self._answer(seq, batch)
        finally:
            if self._physics_done:
                self._tail_s, self._physics_done = time.perf_counter() - self._physics_done, 0.0

    def _answer(self, seq: int, batch: BatchResult) -> tuple[bool, dict[str, Any] | None]:
        arrays, doorbell = self._arrays, self.doorbell
        if arrays is None or doorbell is None or self._found_tampered():
            return False, None
        if not self._put_arrays(batch):
            return False, None
        columns = self._columns(batch)
        if columns is None:
            return False, {"shared": True, "final": []}
        n = len(batch.reward)
        views = self._column_views
        for c, (_, values, _) in enumerate(columns):
            key = (c, values.dtype, n)
            view = views.get(key)
            if view is None:
                view = views[key] = arrays.info_column(c, values.dtype)[:n]
            view[...] = values
        signature = tuple([(key, values.dtype, python) for key, values, python in columns])
        if signature != self._info_signature:
            self._info_version += 1
            self._info_signature = signature
            layout = {
                "version": self._info_version,
                "columns": [[key, dtype.str, python] for key, dtype, python in signature],
            }
            return False, {"shared": True, "final": [], "info_layout": layout}
        return True, ({"region": True} if doorbell.reply(seq, self._info_version) else None)

    def obs_rows(self, n: int) -> np.ndarray | None:
        """The region's observation rows ``0 .. n-1``, where a step may write its
        observations directly (camera images rendered in place: no copy); None
        before the region exists."""
        rows = self._rows(n)
        return None if rows is None else rows[0]

    def _rows(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The region's obs, reward, terminated and truncated rows ``0 .. n-1`` (None: no region, or ``n`` off)."""
        rows = self._row_views.get(n)
        if rows is None:
            arrays = self._arrays
            if arrays is None or not 0 < n <= len(arrays.obs):
                return None
            rows = self._row_views[n] = (arrays.obs[:n], arrays.reward[:n], arrays.terminated[:n], arrays.truncated[:n])
        return rows

    def _put_arrays(self, batch: BatchResult) -> bool:
        obs = batch.obs
        if not isinstance(obs, np.ndarray):
            return False
        rows = self._rows(len(batch.reward))
        if rows is None:
            return False
        obs_rows, reward, terminated, truncated = rows
        if obs.dtype != obs_rows.dtype or obs.shape != obs_rows.shape:
            return False
        # Not written in place (see obs_rows); an array that owns its memory never was.
        if obs is not obs_rows and (obs.base is None or obs.ctypes.data != obs_rows.ctypes.data):
            obs_rows[...] = obs
        reward[...] = batch.reward
        terminated[...] = batch.terminated
        truncated[...] = False
        return True

    def _columns(self, batch: BatchResult) -> list[tuple[str, np.ndarray, bool]] | None:
        """The batch's infos as ``(key, values, python)`` columns the region holds, or None."""
        infos = batch.infos
        n = len(batch.reward)
        if not isinstance(infos, dict) or len(infos) > INFO_COLUMNS:
            return None
        out = []
        for key, values in infos.items():
            if not isinstance(values, np.ndarray) or values.shape != (n,) or values.dtype.kind not in COLUMN_KINDS:
                return None
            python = key in batch.python_scalars
            if python:
                wide = widened(values)
                if wide is None:
                    return None
                values = wide
            elif values.dtype.itemsize > 8:
                return None
            out.append((key, values, python))
        return out

    def close(self) -> None:
        self._column_views.clear()
        self._row_views.clear()
        if self._arrays is not None:
            self._arrays.close()
            self._arrays = None
        self.doorbell = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


__all__ = ["INFO_COLUMNS", "SharedLane", "layout_for"]
