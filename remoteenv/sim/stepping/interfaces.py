"""How worlds advance: the interfaces the server's one loop drives.

Runs in the sim process. Two strategies implement them: lock-step
(:mod:`remoteenv.sim.stepping.lock_step`, the default: a world advances only on a
``step`` request) and real time (:mod:`remoteenv.sim.stepping.real_time`: physics
paced to the wall clock while the agent thinks).

The server's loop asks its :class:`Stepping` for the next deadline on its
clock. None (always, in lock-step) means nothing is due: the loop blocks
until a request arrives. Otherwise the loop waits until that deadline (or
a request), calls :meth:`Stepping.run_due` and sends the replies it yields.
A ``step`` request goes to its world's :class:`WorldStepper`, which answers
at once (lock-step) or records where to answer and does so from
``run_due`` (real time).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, Protocol

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.transport.channels import Channel, Outgoing


class WorldStepper(Protocol):
    """How one world answers ``reset`` and ``step``."""

    @property
    def env(self) -> BaseEnv:
        """The world."""
        ...

    @property
    def has_reset(self) -> bool:
        """Whether the world has been reset since the process started (steps need it)."""
        ...

    def describe(self) -> dict[str, Any]:
        """The handshake's ``stepping`` map: ``mode`` and the mode's parameters."""
        ...

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        """Start an episode; ``(obs, info)``."""
        ...

    def submit(self, seq: int, action: Any, channel: Channel | None, reply_to: Any) -> dict[str, Any] | None:
        """A checked ``step`` request (``seq``, ``action``) that came on ``channel`` from ``reply_to``.

        Returns the reply's fields to send at once, or None when the reply
        will come later from :meth:`Stepping.run_due`.
        """
        ...


class Stepping(Protocol):
    """The loop strategy of one server: its worlds and their schedule."""

    @property
    def worlds(self) -> Sequence[WorldStepper]:
        """One stepper per world, in world order."""
        ...

    @property
    def clock_waiting(self) -> bool:
        """A world was reset and its clock starts once the reset's reply is sent."""
        ...

    def next_deadline(self) -> float | None:
        """When, on the stepping's clock (seconds), the next piece of work is due; None if none is."""
        ...

    def start_clocks(self, now: float) -> None:
        """Start the clock of every world waiting for it, at ``now``."""
        ...

    def run_due(self, now: float) -> Iterable[Outgoing]:
        """Do the work due at ``now``; yields the replies it completes, as soon as each is ready."""
        ...


__all__ = ["Stepping", "WorldStepper"]
