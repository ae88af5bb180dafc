"""The ``get_attr``, ``set_attr`` and ``call`` commands: the agent's reach into a scene.

Runs in the sim process. They read, write or call a public attribute of one
world's scene env (its :class:`~remoteenv.sim.scene.base_env.BaseEnv` subclass),
which is how an agent sets different model parameters per world (domain
randomization) or calls a scene's own methods; Gymnasium's vector
``call``/``get_attr``/``set_attr`` and SB3's ``env_method`` reach the scene
through them. The wire form is specified in :mod:`remoteenv.wire.protocol`.

Refused with an ``attribute`` error: private names (``_x``), names the scene
lacks (``set_attr`` never creates one: a typo would pass silently), and the
methods that drive the world (``reset``, ``step``, ...), which only the
stepping may call. A value that cannot cross the wire (an ``MjModel``, say)
gets an ``unsendable`` error naming it, before anything is sent.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.transport.channels import Channel
from remoteenv.sim.transport.checks import RequestError, world_index
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import ATTRIBUTE, PROTOCOL, UNSENDABLE, short_repr

#: BaseEnv methods that drive the world: only the server's stepping calls them.
DRIVING_METHODS = frozenset(
    {
        "reset",
        "step",
        "substep",
        "finish_tick",
        "prepare_step",
        "post_step",
        "reset_model",
        "observe",
        "render",
        "close",
    }
)


class AttributeCommands:
    """``get_attr``, ``set_attr`` and ``call`` over the worlds of one process.

    Args:
        envs: the worlds, in world order.
        instance: this sim process's index (named in error messages).
    """

    def __init__(self, envs: Sequence[BaseEnv], instance: int) -> None:
        self.envs = envs
        self.instance = instance

    def handlers(self) -> dict[str, Any]:
        return {"get_attr": self.get_attr, "set_attr": self.set_attr, "call": self.call}

    def get_attr(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        env, name = self._target(msg)
        value = self._lookup(env, name)
        if callable(value):
            return {"value": None, "callable": True}
        return {"value": self._sendable(value, f"attribute {name!r}", env), "callable": False}

    def set_attr(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        env, name = self._target(msg)
        self._lookup(env, name)
        setattr(env, name, msg.get("value"))
        return {}

    def call(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        env, name = self._target(msg)
        args, kwargs = msg.get("args") or [], msg.get("kwargs") or {}
        if not isinstance(args, list) or not isinstance(kwargs, dict):
            raise RequestError(PROTOCOL, "call needs 'args' as a list and 'kwargs' as a map (or nil)")
        value = self._lookup(env, name)
        if callable(value):
            value = value(*args, **kwargs)
        elif args or kwargs:
            raise RequestError(ATTRIBUTE, f"{self._where(env)}.{name} is not callable; it takes no arguments")
        return {"result": self._sendable(value, f"what {name!r} returned", env)}

    # ------------------------------------------------------------ helpers

    def _target(self, msg: dict[str, Any]) -> tuple[BaseEnv, str]:
        world = world_index(msg, len(self.envs))
        name = msg.get("name")
        if not isinstance(name, str) or not name.isidentifier():
            raise RequestError(PROTOCOL, f"'name' must be an attribute name, got {short_repr(name)}")
        env = self.envs[world]
        if name.startswith("_"):
            raise RequestError(ATTRIBUTE, f"{name!r} is private to {self._where(env)}; only public names are reachable")
        if name in DRIVING_METHODS:
            raise RequestError(
                ATTRIBUTE, f"{name!r} drives the world; use the env's own reset/step/render/close instead"
            )
        return env, name

    def _lookup(self, env: BaseEnv, name: str) -> Any:
        try:
            return getattr(env, name)
        except AttributeError:
            raise RequestError(ATTRIBUTE, f"{self._where(env)} has no attribute {name!r}") from None

    def _sendable(self, value: Any, what: str, env: BaseEnv) -> Any:
        try:
            protocol.pack(value, big_ints=True)
        except (TypeError, ValueError, OverflowError) as exc:
            raise RequestError(
                UNSENDABLE,
                f"{what} on {self._where(env)} cannot cross the wire ({exc}); return numpy arrays, "
                "numbers, strings, lists and str-keyed maps (e.g. a method that reads what you need)",
            ) from None
        return value

    def _where(self, env: BaseEnv) -> str:
        return f"{type(env).__name__} (world {self.envs.index(env)} of sim instance {self.instance})"


__all__ = ["DRIVING_METHODS", "AttributeCommands"]
