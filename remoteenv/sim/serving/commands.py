"""The commands every sim server answers: handshake, reset, step, render, close.

Runs in the sim process. Each handler takes the decoded request, the channel
it came on and whom to answer there, and returns the reply's fields (the
server adds ``seq`` and ``ok``), or None when the reply comes later (a
real-time step). A refused request raises
:class:`~remoteenv.sim.transport.checks.RequestError` or
:class:`~remoteenv.wire.wire_errors.InvalidAction`; the server turns either into a
typed error reply. The wire form of each command is specified in
:mod:`remoteenv.wire.protocol`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.world_cost import measured_cost
from remoteenv.sim.stepping.interfaces import Stepping
from remoteenv.sim.transport.channels import Channel
from remoteenv.sim.transport.checks import (
    options_value,
    protocol_version,
    require_reset,
    seed_value,
    world_index,
)
from remoteenv.sim.transport.drivers import Drivers
from remoteenv.wire import protocol
from remoteenv.wire.codec import spaces as spaces_codec
from remoteenv.wire.codec.scalar_types import describe_scalars
from remoteenv.wire.messages.action_rules import check_action

#: A command handler: ``(request, channel, reply_to) -> reply fields``, or None
#: when the reply will be sent later.
Handler = Callable[[dict[str, Any], "Channel | None", Any], "dict[str, Any] | None"]
#: The handler of a request found posted in the pipe's region (its decoded map and the pipe).
RegionHandler = Callable[[dict[str, Any], "Channel | None"], "dict[str, Any] | None"]


class Commands:
    """The commands common to both stepping modes, for the worlds of one process.

    Args:
        envs: the worlds, in world order.
        stepping: how they advance (its ``worlds`` match ``envs``).
        instance: this sim process's index (reported in the handshake, named in errors).
        stop: called by ``close`` to end serving once the reply is sent.
        launcher_channel: the launching agent's local pipe, if any.
        world_factory: makes a scratch world like ``envs[0]``, for measuring what
            one costs (:func:`~remoteenv.sim.scene.world_cost.measured_cost`); None: estimate it.

    One connection drives each world, in both modes (:mod:`remoteenv.sim.transport.drivers`):
    the launching agent's pipe if there is one, else the connection that
    reset the world last. ``step`` (and, while the pipe drives, ``reset``)
    from any other connection is refused with a ``state`` error, and so is
    ``close`` from a connection that does not drive every driven world; the
    other commands here are open to every connection.
    """

    def __init__(
        self,
        envs: Sequence[BaseEnv],
        stepping: Stepping,
        instance: int,
        stop: Callable[[], None],
        launcher_channel: Channel | None = None,
        world_factory: Callable[[], BaseEnv] | None = None,
    ) -> None:
        self.envs = envs
        self.world_factory = world_factory
        self.stepping = stepping
        #: Every command the server answers, sent in the handshake (the server fills it in).
        self.advertised: list[str] = []
        #: How a lock-step process steps its worlds' physics, sent in the handshake's
        #: metadata (the server fills it in, :meth:`~remoteenv.sim.stepping.batch_commands.BatchCommands.physics`).
        self.physics: dict[str, Any] = {}
        self._worlds = stepping.worlds
        self.instance = instance
        self._stop = stop
        #: Who drives each world (and so may step it, and close the sim).
        self.drivers = Drivers(len(envs), instance, launcher_channel)

    def handlers(self) -> dict[str, Handler]:
        return {
            "handshake": self.handshake,
            "reset": self.reset,
            "step": self.step,
            "render": self.render,
            "close": self.close,
        }

    def handshake(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        protocol_version(msg.get("protocol"), protocol.PROTOCOL_VERSION, self.instance)
        env = self.envs[0]
        metadata: dict[str, Any] = {
            "render_modes": list(env.metadata.get("render_modes", [])),
            "render_fps": int(round(1.0 / env.dt)),
            "dt": float(env.dt),
            "timestep": float(env.model.opt.timestep),
            "frame_skip": env.frame_skip,
            **self.physics,
        }
        if msg.get("world_cost") is True:
            metadata["world_cost_s"] = self._world_cost(on_world_0=msg.get("probe") is True)
        return {
            "protocol": protocol.PROTOCOL_VERSION,
            "env_id": env.env_id,
            "instance": self.instance,
            "pid": os.getpid(),
            "num_worlds": len(self.envs),
            "observation_space": spaces_codec.space_to_wire(env.observation_space),
            "action_space": spaces_codec.space_to_wire(env.action_space),
            "metadata": metadata,
            "stepping": self._worlds[0].describe(),
            "commands": list(self.advertised),
        }

    def _world_cost(self, on_world_0: bool = False) -> float:
        """What one world's control tick costs (:func:`~remoteenv.sim.scene.world_cost.measured_cost`),
        measured once; ``on_world_0`` (a probe's handshake): on the served world 0 itself."""
        cost = getattr(self, "_cost", None)
        if cost is None:
            cost = self._cost = measured_cost(self.envs[0], self.world_factory, on_world=on_world_0)
        return cost

    def reset(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        world = world_index(msg, len(self.envs))
        seed = seed_value(msg.get("seed"))
        options = options_value(msg.get("options"))
        self.drivers.take((world,), (channel, reply_to), "reset")
        obs, info = self._worlds[world].reset(seed=seed, options=options)
        return describe_scalars({"obs": obs, "info": info})

    def step(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any] | None:
        world = world_index(msg, len(self.envs))
        stepper = self._worlds[world]
        require_reset(stepper.has_reset, world, self.instance)
        action = check_action(self.envs[world].action_space, msg.get("action"))  # the same answer for anyone
        self.drivers.take((world,), (channel, reply_to), "step")
        reply = stepper.submit(msg["seq"], action, channel, reply_to)
        return None if reply is None else describe_scalars(reply)

    def render(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        world = world_index(msg, len(self.envs))
        return {"frame": self.envs[world].render()}

    def close(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        self.drivers.require_every((channel, reply_to), "close")
        self._stop()
        return {}


__all__ = ["Commands", "Handler"]
