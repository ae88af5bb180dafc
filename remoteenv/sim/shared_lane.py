"""The sim's end of the shared-memory region of the local pipe (``shared_batch``).

Runs in the sim process (lock-step). The launching agent asks for the region
once with ``shared_batch``; after that its ``step_batch`` requests may carry
``"shared": true`` instead of ``actions`` (read from the region), and a
plain step (every world stepped, none reset) answers with its arrays in the
region. Layout and rules: :mod:`remoteenv.wire.shared_batch`; wire form:
:mod:`remoteenv.wire.protocol`. Only the launching agent's pipe may use it:
a ZeroMQ client gets a ``state`` error.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim.batch_result import BatchResult
from remoteenv.sim.channels import Channel, PipeChannel
from remoteenv.sim.checks import RequestError
from remoteenv.wire.arrays import wire_dtype
from remoteenv.wire.errors import PROTOCOL, STATE
from remoteenv.wire.shared_batch import SharedArrays, SharedLayout, create_region


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


class SharedLane:
    """The region of one sim process's worlds, created on the agent's first ``shared_batch``.

    Args:
        action_space, obs_space: the worlds' spaces.
        worlds: how many worlds the process hosts.
    """

    def __init__(self, action_space: spaces.Space, obs_space: spaces.Space, worlds: int) -> None:
        self.layout = layout_for(action_space, obs_space, worlds)
        self._fd: int | None = None
        self._arrays: SharedArrays | None = None

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
        return {"pid": os.getpid(), "fd": self._fd, "layout": self.layout.to_wire()}

    def actions(self, n: int, channel: Channel | None) -> np.ndarray:
        """A copy of the actions of request positions ``0 .. n-1`` (checked by the caller)."""
        arrays = self._arrays
        if arrays is None or not isinstance(channel, PipeChannel):
            raise RequestError(STATE, "a 'shared' step_batch needs the region of shared_batch, over the local pipe")
        if not 0 < n <= len(arrays.actions):
            raise RequestError(PROTOCOL, f"a 'shared' step_batch covers 1..{len(arrays.actions)} worlds, got {n}")
        return arrays.actions[:n].copy()

    def reply(self, batch: BatchResult, info: dict[str, Any]) -> dict[str, Any] | None:
        """Put a plain step's arrays in the region and return the reply's other
        fields; None if the obs batch does not fit the layout (then the caller
        answers the usual way)."""
        arrays = self._arrays
        obs = batch.obs
        if arrays is None or not isinstance(obs, np.ndarray):
            return None
        n = len(batch.reward)
        if obs.dtype != arrays.obs.dtype or obs.shape != arrays.obs[:n].shape:
            return None
        arrays.obs[:n] = obs
        arrays.reward[:n] = batch.reward
        arrays.terminated[:n] = batch.terminated
        arrays.truncated[:n] = False
        return {"shared": True, "info": info, "final": []}

    def close(self) -> None:
        if self._arrays is not None:
            self._arrays.close()
            self._arrays = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


__all__ = ["SharedLane", "layout_for"]
