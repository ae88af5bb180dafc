"""The sim server's command table: which commands it answers, a request
dispatched to its handler, a reply encoded, none of it ever raising.

Runs in the sim process (:class:`~remoteenv.sim.serving.sim_server.RemoteControlledAgent`
holds one). :func:`build_table` puts together the common commands
(:mod:`~remoteenv.sim.serving.commands`), the scene-attribute commands
(:mod:`~remoteenv.sim.serving.attributes`) and those of the stepping mode
(:mod:`~remoteenv.sim.serving.stepping_modes`), guarded by the driver rule
(:mod:`remoteenv.sim.transport.drivers`). :meth:`CommandTable.handle` turns
every failure of a handler into a typed error reply (``protocol``,
``invalid_action`` or ``scene``, see :mod:`remoteenv.wire.protocol`), and
:func:`pack_reply` turns a reply that cannot go on the wire into one too.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.serving.attributes import AttributeCommands
from remoteenv.sim.serving.commands import Commands, Handler, RegionHandler
from remoteenv.sim.serving.stepping_modes import stepping_and_commands
from remoteenv.sim.stepping.interfaces import Stepping
from remoteenv.sim.stepping.plain_region_step import PlainRegionStep
from remoteenv.sim.stepping.real_time import Clock
from remoteenv.sim.transport.channels import Channel, PipeChannel
from remoteenv.sim.transport.checks import RequestError
from remoteenv.sim.transport.drivers import Drivers
from remoteenv.wire import protocol
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.wire_errors import INVALID_ACTION, PROTOCOL, SCENE, InvalidAction, short_repr


class CommandTable:
    """Command name -> handler; :meth:`handle` answers a decoded request with it."""

    def __init__(
        self, handlers: dict[str, Handler], region: RegionHandler | None = None, plain: PlainRegionStep | None = None
    ) -> None:
        self.handlers = handlers
        #: The handler of the requests found posted in the pipe's region (lock-step), or None.
        self.region = region
        #: Those of them that step every world plainly, served without the dispatch (lock-step), or None.
        self.plain = plain

    @property
    def commands(self) -> list[str]:
        """The commands in the table, sorted."""
        return sorted(self.handlers)

    def handle(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any] | None:
        """The reply to a decoded request (never raises), or None if it comes later
        (see :meth:`remoteenv.sim.serving.sim_server.RemoteControlledAgent.handle`)."""
        seq = msg["seq"]
        handler = self.handlers.get(msg["cmd"])
        if handler is None:
            return protocol.error_reply(
                seq, PROTOCOL, f"unknown command {short_repr(msg['cmd'])}; known: {sorted(self.handlers)}"
            )
        return self._answered(seq, handler, msg, channel, reply_to)

    def handle_region(self, msg: dict[str, Any], pipe: Channel) -> dict[str, Any] | None:
        """:meth:`handle` for a request the launching agent's ``pipe`` found
        posted in its region (:func:`~remoteenv.wire.protocol.region_request`):
        straight to the region's handler, as its ``step_batch`` would reach it
        (that pipe drives every world: the driver rule lets it through)."""
        if self.region is None:
            return self.handle(msg, pipe, None)
        return self._answered(msg["seq"], self.region, msg, pipe)

    def handle_plain_region(self, seq: int, pipe: Channel) -> tuple[bool, dict[str, Any] | None]:
        """Request ``seq``, found posted in the launching agent's ``pipe``'s
        region, if it is a plain step of every world (:attr:`plain`):
        ``(True, reply)``, served (the reply :meth:`handle_region` would give;
        None: answered in the region); ``(False, None)``, not taken: serve it
        with :meth:`handle_region`. Never raises."""
        plain = self.plain
        if plain is None:
            return False, None
        actions = plain.take(seq, pipe)
        if actions is None:
            return False, None
        return True, self._answered(seq, plain.step, actions, seq)

    def _answered(self, seq: int, handler: Callable[..., dict[str, Any] | None], *args: Any) -> dict[str, Any] | None:
        """``handler(*args)``'s reply to request ``seq``, every failure a typed error reply."""
        try:
            reply = handler(*args)
        except RequestError as exc:
            return protocol.error_reply(seq, exc.kind, str(exc))
        except InvalidAction as exc:
            return protocol.error_reply(seq, INVALID_ACTION, str(exc))
        except Exception as exc:
            return protocol.error_reply(seq, SCENE, f"{type(exc).__name__}: {exc}", traceback.format_exc())
        if reply is not None:
            reply["seq"] = seq
            reply["ok"] = True
        return reply


def build_table(
    envs: list[BaseEnv],
    instance: int,
    stop: Callable[[], None],
    pipe: PipeChannel | None,
    run: RunOptions,
    *,
    seed: int | None,
    clock: Clock,
    world_factory: Callable[[], BaseEnv] | None = None,
) -> tuple[Stepping, CommandTable, Drivers]:
    """The stepping strategy, command table and driver rule of a server of
    ``envs`` run as ``run`` says. ``stop`` ends serving (``close``); ``pipe`` is
    the launcher's channel, if any; ``seed`` and ``clock`` are
    :func:`~remoteenv.sim.serving.stepping_modes.stepping_and_commands`'s;
    ``world_factory`` makes a scratch world for the handshake's cost
    measurement (:class:`~remoteenv.sim.serving.commands.Commands`)."""
    stepping, mode_commands, physics, region, plain = stepping_and_commands(envs, instance, run, seed=seed, clock=clock)
    common = Commands(envs, stepping, instance, stop, launcher_channel=pipe, world_factory=world_factory)
    common.physics = physics
    handlers: dict[str, Handler] = common.handlers()
    handlers.update(AttributeCommands(envs, instance).handlers())
    handlers.update(mode_commands)
    drivers = common.drivers
    for name in ("pause", "resume"):  # they stop or start every world's clock
        if name in handlers:
            handlers[name] = drivers.guard_every(name, handlers[name])
    if "reset_batch" in handlers:
        handlers["reset_batch"] = drivers.guard_reset_batch(handlers["reset_batch"])
        handlers["step_batch"] = drivers.guard_step_batch(handlers["step_batch"])
    common.advertised = sorted(handlers)
    return stepping, CommandTable(handlers, region, plain), drivers


def pack_reply(reply: dict[str, Any]) -> bytes:
    """Encode a reply; one that cannot go on the wire becomes a typed error (never raises)."""
    try:
        return protocol.pack(reply, big_ints=True)
    except protocol.FrameTooLarge as exc:
        seq = reply.get("seq", -1)
        return protocol.pack(
            protocol.error_reply(
                seq if isinstance(seq, int) else -1,
                PROTOCOL,
                f"the reply to this request is too large to send: {exc}; ask for less "
                "(e.g. a smaller render size or fewer worlds per batch)",
            )
        )
    except Exception as exc:
        seq = reply.get("seq", -1)
        return protocol.pack(
            protocol.error_reply(
                seq if isinstance(seq, int) else -1,
                SCENE,
                f"the reply to this request cannot be sent on the wire ({type(exc).__name__}: "
                f"{short_repr(str(exc))}); "
                "scene code must return numpy arrays, numbers, strings, lists and str-keyed maps",
                traceback.format_exc(),
            )
        )


__all__ = ["CommandTable", "build_table", "pack_reply"]
