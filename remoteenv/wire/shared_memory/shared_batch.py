"""The shared-memory region of a local pipe's batched steps (the spec's
``shared_batch``, see :mod:`remoteenv.wire.protocol`). Both processes use it.

A sim process serving its launching agent over the local pipe can put the
arrays of a plain ``step_batch`` (every world stepped, none reset) in memory
both processes map, so the pipe carries only the small rest of the request
and reply (ops, infos). The sim creates the region (an anonymous
``memfd``: nothing on disk, gone when both ends close it) and, before it
offers it, seals its size (:data:`REGION_SEALS`: ``F_SEAL_SHRINK``,
``F_SEAL_GROW``, ``F_SEAL_SEAL``) so no process can truncate it under a
mapping; the agent maps the same file through ``/proc/<sim pid>/fd/<fd>``. Layout, for ``K`` worlds, each
block starting on a 64-byte boundary in this order:

- ``actions``: ``K`` rows of the action (Box: its dtype and shape; Discrete:
  ``<i8`` scalars), written by the agent before it sends the request;
- ``obs``: ``K`` rows of the observation (Box: its dtype and shape);
- ``reward``: ``K`` ``<f8``; ``terminated``, ``truncated``: ``K`` ``|b1``;
  written by the sim before it sends the reply.

A region laid out with ``info_columns = M > 0`` (the fast lane, see
:mod:`remoteenv.wire.shared_memory.doorbell`) continues with:

- ``header``: 16 ``<i8`` words, the doorbell's (words 0-7 written by the
  agent, 8-15 by the sim; see :mod:`remoteenv.wire.shared_memory.doorbell`);
- ``ops``: ``K`` ``|i1``, the request's ops; ``worlds``: ``K`` ``<i4``, the
  worlds it addresses when it names them (both written by the agent);
- ``info``: ``M`` columns of ``K`` values of at most 8 bytes each (column
  ``c`` starts at byte ``c * 8 * K`` of the block), written by the sim, laid
  out as the sim last announced (a ``step_batch`` reply's ``info_layout``).

Row ``j`` belongs to request position ``j``. Each side writes its blocks only
while the other waits for the message that follows, so the pipe (or the
doorbell's sequence words) orders every access. The sim checks the ops,
worlds and actions it reads like sent ones; the agent reads numbers of a
fixed dtype and shape, nothing it would interpret further.

The agent maps only a region sealed against shrinking (:func:`map_region`):
truncating a mapped file would turn its next access into ``SIGBUS``, a
signal that kills the process instead of an error it can handle.
"""

from __future__ import annotations

import fcntl
import math
import mmap
import os
import stat
from dataclasses import dataclass
from typing import Any

import numpy as np

from remoteenv.wire.codec.arrays import ARRAY_DTYPES
from remoteenv.wire.wire_errors import ProtocolError, short_repr

#: Largest region (bytes) either side creates or maps.
MAX_SHARED_BYTES = 1 << 28
_ALIGN = 64
_MAX_WORLDS = 1 << 16
_MAX_NDIM = 8
#: Most info columns a region's fast lane holds.
MAX_INFO_COLUMNS = 64
#: Words of the doorbell's header (two 64-byte lines of ``<i8``).
HEADER_WORDS = 16


def _aligned(n: int) -> int:
    return (n + _ALIGN - 1) // _ALIGN * _ALIGN


def _block(value: Any, what: str) -> tuple[str, tuple[int, ...]]:
    """A ``[dtype, shape]`` wire pair, checked."""
    if not (isinstance(value, list) and len(value) == 2 and isinstance(value[0], str) and isinstance(value[1], list)):
        raise ProtocolError(f"shared_batch layout: {what} must be [dtype, shape], got {short_repr(value)}")
    dtype, shape = value
    if dtype not in ARRAY_DTYPES:
        raise ProtocolError(f"shared_batch layout: {what} dtype {short_repr(dtype)} is not allowed")
    if len(shape) > _MAX_NDIM or not all(type(d) is int and 0 < d <= MAX_SHARED_BYTES for d in shape):
        raise ProtocolError(f"shared_batch layout: {what} shape {short_repr(shape)} is not allowed")
    return dtype, tuple(shape)


@dataclass(frozen=True)
class SharedLayout:
    """Where each block of a region lies (see the module doc)."""

    worlds: int
    action_dtype: str
    action_shape: tuple[int, ...]
    obs_dtype: str
    obs_shape: tuple[int, ...]
    #: Info columns of the fast lane (0: the region has no lane blocks).
    info_columns: int = 0

    def _blocks(self) -> list[tuple[str, str, tuple[int, ...]]]:
        k = self.worlds
        blocks = [
            ("actions", self.action_dtype, (k, *self.action_shape)),
            ("obs", self.obs_dtype, (k, *self.obs_shape)),
            ("reward", "<f8", (k,)),
            ("terminated", "|b1", (k,)),
            ("truncated", "|b1", (k,)),
        ]
        if self.info_columns:
            blocks += [
                ("header", "<i8", (HEADER_WORDS,)),
                ("ops", "|i1", (k,)),
                ("worlds", "<i4", (k,)),
                ("info", "|u1", (self.info_columns, 8 * k)),
            ]
        return blocks

    @property
    def size(self) -> int:
        """Bytes the region needs."""
        total = 0
        for _, dtype, shape in self._blocks():
            total += _aligned(np.dtype(dtype).itemsize * math.prod(shape))
        return total

    def to_wire(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "worlds": self.worlds,
            "actions": [self.action_dtype, list(self.action_shape)],
            "obs": [self.obs_dtype, list(self.obs_shape)],
        }
        if self.info_columns:
            out["info_columns"] = self.info_columns
        return out

    @classmethod
    def from_wire(cls, value: Any) -> SharedLayout:
        """The layout a peer sent; :class:`ProtocolError` if anything is off or too large."""
        if not isinstance(value, dict):
            raise ProtocolError(f"shared_batch layout must be a map, got {short_repr(value)}")
        worlds = value.get("worlds")
        if type(worlds) is not int or not 0 < worlds <= _MAX_WORLDS:
            raise ProtocolError(f"shared_batch layout: worlds must be 1..{_MAX_WORLDS}, got {short_repr(worlds)}")
        action_dtype, action_shape = _block(value.get("actions"), "actions")
        obs_dtype, obs_shape = _block(value.get("obs"), "obs")
        columns = value.get("info_columns", 0)
        if type(columns) is not int or not 0 <= columns <= MAX_INFO_COLUMNS:
            raise ProtocolError(
                f"shared_batch layout: info_columns must be 0..{MAX_INFO_COLUMNS}, got {short_repr(columns)}"
            )
        layout = cls(worlds, action_dtype, action_shape, obs_dtype, obs_shape, columns)
        if layout.size > MAX_SHARED_BYTES:
            raise ProtocolError(f"shared_batch region of {layout.size} bytes exceeds {MAX_SHARED_BYTES}")
        return layout


class SharedArrays:
    """numpy views of the blocks of one mapped region (see :class:`SharedLayout`)."""

    def __init__(self, layout: SharedLayout, region: mmap.mmap) -> None:
        self.layout = layout
        self._region = region
        offset = 0
        views: dict[str, np.ndarray] = {}
        for name, dtype, shape in layout._blocks():
            dt = np.dtype(dtype)
            views[name] = np.ndarray(shape, dtype=dt, buffer=region, offset=offset)
            offset += _aligned(dt.itemsize * math.prod(shape))
        self.actions = views["actions"]
        self.obs = views["obs"]
        self.reward = views["reward"]
        self.terminated = views["terminated"]
        self.truncated = views["truncated"]
        #: The fast lane's blocks (None without them, see :attr:`SharedLayout.info_columns`).
        self.header: np.ndarray | None = views.get("header")
        self.ops: np.ndarray | None = views.get("ops")
        self.worlds: np.ndarray | None = views.get("worlds")
        self.info: np.ndarray | None = views.get("info")

    def info_column(self, c: int, dtype: np.dtype) -> np.ndarray:
        """Info column ``c`` of the lane as ``K`` values of ``dtype`` (itemsize at most 8)."""
        assert self.info is not None
        k = self.layout.worlds
        return self.info[c, : k * dtype.itemsize].view(dtype)

    def close(self) -> None:
        """Drop the views and unmap the region (later use of the views is an error)."""
        for name in ("actions", "obs", "reward", "terminated", "truncated", "header", "ops", "worlds", "info"):
            setattr(self, name, None)
        try:
            self._region.close()
        except BufferError:  # a view someone kept: the mapping goes with it
            pass


#: The seals :func:`create_region` sets on the region's ``memfd`` once it has its
#: size, before the region is offered: its size is fixed for good (a shrunk
#: file would kill a process that maps it with SIGBUS), and no seal may be
#: added or removed afterwards. Writes stay allowed: both sides write it.
REGION_SEALS = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL if hasattr(fcntl, "F_SEAL_SHRINK") else 0


def create_region(layout: SharedLayout) -> tuple[int, SharedArrays]:
    """A new anonymous region for ``layout``: its file descriptor and views (sim side).

    The ``memfd`` is created with ``MFD_ALLOW_SEALING`` and, once sized, sealed
    with :data:`REGION_SEALS` (``F_SEAL_SHRINK | F_SEAL_GROW | F_SEAL_SEAL``),
    so neither this process nor any other can change its size afterwards.
    """
    flags = getattr(os, "MFD_CLOEXEC", 0) | getattr(os, "MFD_ALLOW_SEALING", 0)
    fd = os.memfd_create("remoteenv-shared-batch", flags)
    try:
        os.ftruncate(fd, layout.size)
        if REGION_SEALS:
            fcntl.fcntl(fd, fcntl.F_ADD_SEALS, REGION_SEALS)
        region = mmap.mmap(fd, layout.size)
    except BaseException:
        os.close(fd)
        raise
    return fd, SharedArrays(layout, region)


class UnsealedRegion(OSError):
    """The region's file is not sealed against shrinking: mapping it would let
    its creator end the mapping process with ``SIGBUS`` by truncating it."""


def map_region(path: str, layout: SharedLayout) -> SharedArrays:
    """Map the region a peer created, opened by ``path`` (agent side).

    Raises ``OSError`` if it cannot be opened, is not a regular file or is
    smaller than ``layout`` needs, and :class:`UnsealedRegion` if it lacks the
    ``F_SEAL_SHRINK`` seal (where the system has seals): a region that can
    shrink under its mapping turns the next access into ``SIGBUS``, which
    kills the process instead of raising."""
    fd = os.open(path, os.O_RDWR | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise OSError(f"{path} is not a regular file")
        if info.st_size < layout.size:
            raise OSError(f"{path} is smaller than the {layout.size} bytes its layout needs")
        shrink_seal = getattr(fcntl, "F_SEAL_SHRINK", None)
        if shrink_seal is not None and not fcntl.fcntl(fd, fcntl.F_GET_SEALS) & shrink_seal:
            raise UnsealedRegion(f"{path} is not sealed against shrinking (F_SEAL_SHRINK)")
        region = mmap.mmap(fd, layout.size)
    finally:
        os.close(fd)
    return SharedArrays(layout, region)


__all__ = [
    "HEADER_WORDS",
    "MAX_INFO_COLUMNS",
    "MAX_SHARED_BYTES",
    "REGION_SEALS",
    "SharedArrays",
    "SharedLayout",
    "UnsealedRegion",
    "create_region",
    "map_region",
]
