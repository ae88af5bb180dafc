"""Who may drive a sim's worlds and stop the sim: the driver rule, in both stepping modes.

Runs in the sim process. A connection is a ``(channel, routing id)`` pair:
the launching agent's local pipe is ``(pipe, None)``, a ZeroMQ peer
``(router channel, its routing id)`` (an agent keeps its routing id across
the reconnect after a timeout, so it stays the same connection).

- Each world has one driver. With a launching pipe, the pipe drives every
  world for good. Without one, nobody drives a world until a connection
  resets or steps it; that connection then drives it, and a driven world
  stays its driver's until the driver's connection ends (the ROUTER reports
  the disconnect, :meth:`Drivers.release`): a reset from any other
  connection is refused, so a second client cannot take over the world of
  an agent attached to a ``launch``ed sim.
- ``step``, ``step_batch``, ``reset`` and ``reset_batch`` on a driven world
  are refused to any other connection with a ``state`` error. So are the
  commands that act on every world (``close``, ``pause``, ``resume``): they
  need a connection that drives every world somebody drives; the sim's
  *owner*, who may ``close`` it, is the launching pipe, else the connection
  that drives its worlds.
- Everything else (``handshake``, ``render``, ``timing``, the attribute
  commands) is open to every connection that reaches the endpoint.

This rule keeps a second client from stepping, resetting, pausing or
stopping a sim someone else drives; it does not tell users apart. Who may
connect at all is the endpoint's business: an ipc socket in a 0700 dir,
CURVE with the launcher's client key, or (plain tcp on loopback) every
local user.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from remoteenv.sim.transport.checks import require_driver, world_list

#: A connection: ``(channel, routing id)``; the pipe's routing id is None.
Sender = tuple[Any, Any]
#: A handler: ``(request, channel, reply_to) -> reply fields`` (see :mod:`remoteenv.sim.serving.commands`).
_Handler = Any


class Drivers:
    """The driver of each of a sim process's ``num_worlds`` worlds.

    Args:
        num_worlds: how many worlds the process hosts.
        instance: the process's index (named in refusals).
        launcher_channel: the launching agent's local pipe, if any: it then
            drives every world, and nobody can take one over.
    """

    def __init__(self, num_worlds: int, instance: int, launcher_channel: Any = None) -> None:
        self.instance = instance
        self.num_worlds = num_worlds
        self.pipe = launcher_channel
        self._launcher: Sender | None = None if launcher_channel is None else (launcher_channel, None)
        self._by_world: list[Sender | None] = [self._launcher] * num_worlds
        #: The one connection that drives every world, if one does (a shortcut for the checks).
        self._sole: Sender | None = self._launcher
        #: Routing ids of the ZeroMQ connections that drive a world (served first by the ROUTER channel).
        self.routing_ids: frozenset[Any] = frozenset()

    def driver(self, world: int) -> Sender | None:
        """The connection driving ``world`` (None: nobody yet)."""
        return self._by_world[world]

    # ------------------------------------------------------------ checks

    def take(self, worlds: Iterable[int], sender: Sender, cmd: str) -> None:
        """``sender`` resets (or steps) ``worlds``: it becomes the driver of those
        nobody drives; refused (nothing taken) if another connection drives one."""
        worlds = list(worlds)
        if sender == self._sole:
            return
        by_world = self._by_world
        for world in worlds:
            require_driver(by_world[world], sender, world, self.instance, cmd)
        changed = False
        for world in worlds:
            if by_world[world] is None:
                by_world[world] = sender
                changed = True
        if changed:
            self._update()

    def release(self, sender: Sender) -> None:
        """``sender``'s connection ended: the worlds it drove are nobody's (never the pipe's)."""
        if sender == self._launcher:
            return
        changed = False
        for world, driver in enumerate(self._by_world):
            if driver == sender:
                self._by_world[world] = None
                changed = True
        if changed:
            self._update()

    def require(self, worlds: Iterable[int], sender: Sender, cmd: str) -> None:
        """Refuse ``cmd`` on ``worlds`` unless ``sender`` drives each (or nobody drives it yet)."""
        if sender == self._sole:
            return
        by_world = self._by_world
        for world in worlds:
            require_driver(by_world[world], sender, world, self.instance, cmd)

    def require_every(self, sender: Sender, cmd: str) -> None:
        """Refuse ``cmd`` (it acts on every world: ``close``, ``pause``, ``resume``) unless
        ``sender`` drives every world that somebody drives."""
        self.require(range(self.num_worlds), sender, cmd)

    def _update(self) -> None:
        first = self._by_world[0]
        self._sole = first if all(d == first for d in self._by_world) else None
        self.routing_ids = frozenset(d[1] for d in self._by_world if d is not None and d[1] is not None)

    # ------------------------------------------------------------ guards

    def guard_reset_batch(self, handler: _Handler) -> _Handler:
        """``handler`` for ``reset_batch``: its worlds become the sender's, unless another drives one (:meth:`take`)."""

        def guarded(msg: dict[str, Any], channel: Any, reply_to: Any) -> Any:
            if self.pipe is None or channel is not self.pipe:
                worlds = world_list(msg.get("worlds"), self.num_worlds)  # the handler's first check
                self.take(worlds, (channel, reply_to), "reset_batch")
            return handler(msg, channel, reply_to)

        return guarded

    def guard_step_batch(self, handler: _Handler) -> _Handler:
        """``handler`` for ``step_batch``: refused unless the sender drives every world it
        names or nobody does (it then drives them, :meth:`take`).

        Worlds the handler would refuse anyway (ill-formed ``ops``/``worlds``)
        are left to it; every world it can act on is checked here first.
        """

        def guarded(msg: dict[str, Any], channel: Any, reply_to: Any) -> Any:
            if self.pipe is None or channel is not self.pipe:
                sender = (channel, reply_to)
                if sender != self._sole:
                    self.take(self._named_worlds(msg), sender, "step_batch")
            return handler(msg, channel, reply_to)

        return guarded

    def guard_every(self, cmd: str, handler: _Handler) -> _Handler:
        """``handler`` for a command that acts on every world (``pause``, ``resume``)."""

        def guarded(msg: dict[str, Any], channel: Any, reply_to: Any) -> Any:
            self.require_every((channel, reply_to), cmd)
            return handler(msg, channel, reply_to)

        return guarded

    def _named_worlds(self, msg: dict[str, Any]) -> list[int]:
        """The worlds in range a ``step_batch`` names (``worlds``, else ``0 .. len(ops)-1``)."""
        worlds = msg.get("worlds")
        if worlds is None:
            ops = msg.get("ops")
            return list(range(min(len(ops), self.num_worlds))) if isinstance(ops, list) else []
        if not isinstance(worlds, list):
            return []
        return [w for w in worlds if type(w) is int and 0 <= w < self.num_worlds]


__all__ = ["Drivers", "Sender"]
