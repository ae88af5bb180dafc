"""The emulated network link of one real-time world (``link_delay``).

Runs in the sim process (:class:`~remoteenv.sim.stepping.real_time_world.RealTimeStepper`
holds one). Each step request is held back by an extra delay in wall seconds,
drawn from the link's own stream of :mod:`remoteenv.wire.delays.delay_line`
(:data:`~remoteenv.wire.delays.delay_line.LINK_STREAM`): seeded by a reset's
seed, or at the first reset that brings none by the world's launch seed
(None: OS entropy), so a seeded run draws the same delays again.
"""

from __future__ import annotations

from typing import Any

from remoteenv.wire.delays.delay_line import LINK_STREAM, DelayStream
from remoteenv.wire.delays.delay_specs import SECONDS, DelaySpec, as_delay
from remoteenv.wire.running_stats import RunningStats


class EmulatedLink:
    """The delays of ``link_delay`` (wall seconds, a number or a spec in seconds;
    None or 0: no emulated link) for a world launched with ``seed``."""

    def __init__(self, link_delay: DelaySpec | float | None, seed: int | None) -> None:
        link = as_delay(0.0 if link_delay is None else link_delay, SECONDS)
        #: The delay's draws (None: no emulated link).
        self.stream: DelayStream | None = None if link.is_zero else DelayStream(link, LINK_STREAM)
        #: Delays drawn (wall seconds).
        self.delays = RunningStats()
        self._launch_seed = seed
        self._seeded = False

    def reset(self, seed: int | None) -> None:
        """A reset with ``seed``: reseed the stream (with the launch seed at the first unseeded reset)."""
        if self.stream is None:
            return
        if seed is None and not self._seeded:
            seed = self._launch_seed
        if seed is not None:
            self.stream.seed(seed)
            self._seeded = True

    def draw(self) -> float:
        """The next request's extra delay (wall seconds; 0.0 without an emulated link)."""
        if self.stream is None:
            return 0.0
        delay = float(self.stream.draw())
        self.delays.add(delay)
        return delay

    def describe(self, out: dict[str, Any]) -> None:
        """Add the link's spec to a handshake's mode description (nothing without a link)."""
        if self.stream is not None:
            out["link_delay_spec"] = self.stream.spec.to_wire()


__all__ = ["EmulatedLink"]
