"""Reaching a scene's attributes and methods from the agent: ``get_attr``,
``set_attr`` and ``call`` requests to one world of one sim.

Runs in the agent process. :class:`SceneReach` sends the three commands of
the spec (:mod:`remoteenv.wire.protocol`) over a
:class:`~remoteenv.agent.session.sim_session.SimSession`; both env classes build their
Gymnasium-facing ``call``/``get_attr``/``set_attr`` (and the single env's
``get_wrapper_attr``) on it. A scene method read with :meth:`SceneReach.get`
comes back as a :class:`SceneMethod`, a callable that calls it remotely, so
``env.get_wrapper_attr("name")(*args)`` works as for an in-process env.

Errors: a private name is refused here before anything is sent; the sim
refuses names its scene lacks (:class:`~remoteenv.agent.errors.SceneAttributeError`,
an ``AttributeError``) and values that cannot cross the wire
(:class:`~remoteenv.agent.errors.UnsendableValueError`, a ``TypeError``); an
argument that cannot be encoded raises ``TypeError`` here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from remoteenv.agent.errors import RemoteEnvError

if TYPE_CHECKING:
    from remoteenv.agent.session.sim_session import SimSession

#: The commands of this module, as a handshake's ``commands`` lists them.
COMMANDS = ("get_attr", "set_attr", "call")


def check_public(name: Any) -> str:
    """``name`` if it is a public attribute name; ``AttributeError`` (private) or ``TypeError``."""
    if not isinstance(name, str):
        raise TypeError(f"an attribute name must be a str, got {type(name).__name__}")
    if name.startswith("_"):
        raise AttributeError(f"{name!r} is private to the scene; only public names can be reached")
    return name


class SceneMethod:
    """A scene env's method, called in its sim on each call (see :meth:`SceneReach.call`)."""

    def __init__(self, reach: SceneReach, index: int, world: int, name: str) -> None:
        self._reach, self._index, self._world, self.name = reach, index, world, name

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self._reach.call(self._index, self._world, self.name, args, kwargs)

    def __repr__(self) -> str:
        return f"<scene method {self.name!r} of world {self._world} of sim {self._index}>"


class SceneReach:
    """``get_attr``/``set_attr``/``call`` on world ``world`` of sim ``index`` of ``session``."""

    def __init__(self, session: SimSession) -> None:
        self.session = session

    def get(self, index: int, world: int, name: str) -> Any:
        """The attribute's value, or a :class:`SceneMethod` for a method."""
        reply = self._request(index, "get_attr", world=world, name=check_public(name))
        if reply.get("callable"):
            return SceneMethod(self, index, world, name)
        return reply.get("value")

    def set(self, index: int, world: int, name: str, value: Any) -> None:
        """Set an attribute the scene has (the sim never creates one)."""
        self._request(index, "set_attr", world=world, name=check_public(name), value=value)

    def call(
        self, index: int, world: int, name: str, args: Sequence[Any] = (), kwargs: Mapping[str, Any] | None = None
    ) -> Any:
        """Call the scene's method ``name`` (or read a plain attribute when there are no arguments)."""
        reply = self._request(
            index, "call", world=world, name=check_public(name), args=list(args), kwargs=dict(kwargs or {})
        )
        return reply.get("result")

    def _request(self, index: int, cmd: str, **args: Any) -> dict[str, Any]:
        session = self.session
        if not session.closed and not session.handshakes[index].offers(cmd):
            hs = session.handshakes[index]
            raise RemoteEnvError(
                f"sim instance {hs.instance} of {session.label} does not answer {cmd!r} (its handshake "
                "does not list it): it cannot reach scene attributes",
                kind="protocol",
                instance=hs.instance,
            )
        return session.request(index, cmd, **args)


class SceneAttributes:
    """The scene's attributes and methods on a single env (mixed into
    :class:`remoteenv.OpenAIRemoteEnv`): :meth:`call`, :meth:`get_scene_attr`,
    :meth:`set_scene_attr`, and ``get_wrapper_attr``/``set_wrapper_attr``
    falling through to the scene for names the env does not have. Needs
    ``_reach``, a :class:`SceneReach` over the env's session of one sim."""

    _reach: SceneReach

    if not TYPE_CHECKING:  # at run time only: type checkers keep flagging unknown names

        def __getattr__(self, name: str) -> Any:
            raise sim_side_attribute_error(self, name, "get_scene_attr(name) or call(method, ...)")

    def call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        """Call the scene env's public method ``name`` in the sim and return its
        result (for a plain attribute and no arguments: its value), as
        Gymnasium's vector ``call`` does for one env. Arguments and result must
        cross the wire (numbers, strings, numpy arrays, lists, str-keyed maps)."""
        return self._reach.call(0, 0, name, args, kwargs)

    def get_scene_attr(self, name: str) -> Any:
        """The scene env's public attribute ``name`` (a method comes back as a
        callable that calls it in the sim)."""
        return self._reach.get(0, 0, name)

    def set_scene_attr(self, name: str, value: Any) -> None:
        """Set the scene env's public attribute ``name`` (one it has) in the sim."""
        self._reach.set(0, 0, name, value)

    def get_wrapper_attr(self, name: str) -> Any:
        """This env's attribute ``name``, else the scene's (see :meth:`get_scene_attr`)."""
        if hasattr(self, name):
            return getattr(self, name)
        return self.get_scene_attr(name)

    def set_wrapper_attr(self, name: str, value: Any, *, force: bool = True) -> bool:
        """Set ``name`` here if this env has it, else on the scene if it has it;
        otherwise create it here when ``force`` (Gymnasium's rule)."""
        if hasattr(self, name):
            setattr(self, name, value)
            return True
        try:
            self.set_scene_attr(name, value)
            return True
        except AttributeError:  # the scene lacks it (SceneAttributeError), or a private name
            if force:
                setattr(self, name, value)
            return force


#: Attributes of a MuJoCo env that live in the sim process only (the scene's
#: ``MjModel`` and ``MjData``): asking the agent-side env for one says so.
SIM_SIDE_NAMES = frozenset({"model", "data"})


def sim_side_attribute_error(env: Any, name: str, reach: str) -> AttributeError:
    """The ``AttributeError`` for ``env.<name>``, which the env lacks: for the
    sim-side names (:data:`SIM_SIDE_NAMES`) it says where they live and how to reach the scene."""
    if name in SIM_SIDE_NAMES:
        return AttributeError(
            f"{type(env).__name__} has no {name!r}: the scene's MuJoCo {name} lives in the sim process, "
            f"not in this one. Reach the scene with {reach}, e.g. a scene method that returns "
            "what you need as numbers or arrays"
        )
    return AttributeError(f"{type(env).__name__!r} object has no attribute {name!r}")


#: Names a vector env answers itself, as each of its worlds' single env would
#: (value: the vector env's attribute holding it; None: built by the mixin).
_VECTOR_LOCAL = {
    "observation_space": "single_observation_space",
    "action_space": "single_action_space",
    "render_mode": "render_mode",
    "dt": "dt",
    "scene": "scene",
    "spec": "spec",
    "metadata": None,
}


class VectorAttributes:
    """Gymnasium's ``call``/``get_attr``/``set_attr`` for a vector env of remote
    worlds (mixed into :class:`remoteenv.RemoteVectorEnv`).

    Semantics are those of ``SyncVectorEnv`` over single remote envs: a name
    every world's agent-side env has (``observation_space``, ``action_space``
    (the single spaces), ``render_mode``, ``metadata``, ``dt``, ``scene``,
    ``spec``) is answered here; any other name is the scene's, reached in
    each world's sim. ``call`` calls a method (or returns a plain attribute's
    value), ``get_attr`` is ``call`` without arguments, and ``set_attr`` takes
    one value for all worlds or a list/tuple with one per world.
    ``call("render")`` returns each world's frame, as ``SyncVectorEnv``'s
    calls each env's ``render()`` (:meth:`render_world`); so does :meth:`render`.
    :meth:`call_at` and :meth:`set_attr_at` address some worlds only.

    Needs ``num_envs``, ``render_mode``, ``slices`` (``(first, end)`` world
    indices of each sim) and ``_reach`` (a :class:`SceneReach` over the env's
    session).
    """

    num_envs: int
    render_mode: str | None
    slices: list[tuple[int, int]]
    _reach: SceneReach

    if not TYPE_CHECKING:  # at run time only: type checkers keep flagging unknown names

        def __getattr__(self, name: str) -> Any:
            raise sim_side_attribute_error(self, name, "get_attr(name) or call(method, ...) (one result per world)")

    def render_world(self, i: int) -> Any:
        """World ``i``'s frame (None unless ``render_mode="rgb_array"``); ``call("render")`` gives every world's."""
        if self.render_mode != "rgb_array":
            return None
        p, w = self._locate(i)
        return self._reach.session.request(p, "render", world=w)["frame"]

    def render(self) -> tuple[Any, ...] | None:
        """With ``render_mode="rgb_array"``: one uint8 H x W x 3 frame per world."""
        if self.render_mode != "rgb_array":
            return None
        return tuple(self.render_world(i) for i in range(self.num_envs))

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """``name`` called (or read) on every world; one result per world."""
        return self.call_at(range(self.num_envs), name, *args, **kwargs)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """``name`` on every world (a method is called without arguments, as ``SyncVectorEnv`` does)."""
        return self.call(name)

    def set_attr(self, name: str, values: Any) -> None:
        """Set ``name`` on every world: ``values`` is one value for all, or a
        list/tuple of one per world (ValueError for another length)."""
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(
                "Values must be a list or tuple with length equal to the number of environments. "
                f"Got `{len(values)}` values for {self.num_envs} environments."
            )
        self.set_attr_at(range(self.num_envs), name, values)

    def call_at(self, indices: Sequence[int], name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Like :meth:`call`, on the worlds ``indices`` only, in that order."""
        if name == "render" and not args and not kwargs:
            return tuple(self.render_world(i) for i in indices)
        local = self._local_value(name)
        if local is not _MISSING:
            value = local(*args, **kwargs) if callable(local) else local
            return tuple(value for _ in indices)
        return tuple(self._reach.call(*self._locate(i), name, args, kwargs) for i in indices)

    def set_attr_at(self, indices: Sequence[int], name: str, values: Sequence[Any]) -> None:
        """Set ``name`` on the worlds ``indices`` to ``values`` (one per index)."""
        if name in _VECTOR_LOCAL:
            raise AttributeError(
                f"{name!r} belongs to the agent-side env, which all worlds share; it cannot differ per world"
            )
        for i, value in zip(indices, values, strict=True):
            self._reach.set(*self._locate(i), name, value)

    def _locate(self, i: int) -> tuple[int, int]:
        """``(sim index, world in that sim)`` of world ``i``."""
        if not 0 <= i < self.num_envs:
            raise IndexError(f"world {i} out of range; this env has {self.num_envs}")
        for p, (lo, hi) in enumerate(self.slices):
            if lo <= i < hi:
                return p, i - lo
        raise IndexError(f"world {i} is in no sim")  # unreachable: the slices cover every world

    def _local_value(self, name: str) -> Any:
        if name not in _VECTOR_LOCAL:
            return _MISSING
        if name == "metadata":
            meta = getattr(self, "metadata", {})
            return {"render_modes": list(meta.get("render_modes", [])), "render_fps": meta.get("render_fps")}
        return getattr(self, _VECTOR_LOCAL[name] or name, None)


_MISSING = object()

__all__ = ["COMMANDS", "SceneAttributes", "SceneMethod", "SceneReach", "VectorAttributes", "check_public"]
