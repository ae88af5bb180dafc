"""The env a real-time episode ran in, as its recording keeps it (see :mod:`remoteenv.latency_twin`).

Runs in the agent process. :class:`RecordedEnv` is read off a live env when
a recorder wraps it (its constructor arguments, its time limit, and what
its sim's handshake says about real time) and written into the recording
file, so :func:`~remoteenv.latency_twin.make_twin` can build the same env
from the file alone and refuse explicit arguments that contradict it.

What is kept: the keyword arguments that shape the world (the scene's own,
``render_mode``, delay settings; a delay spec as its wire map), the time
limit in steps, ``real_time_factor`` and the emulated ``link_delay`` (as the
sim reported them). What is not: where and how the sim runs
(:data:`PROCESS_KWARGS`: transport, timeouts, restarts, launcher, attach),
which a twin may set freely, and a vector env's own arguments
(:data:`VECTOR_KWARGS`): each world's twin is a single env. An argument
that is neither and cannot be written as JSON is named in
:attr:`RecordedEnv.unrecorded`; the twin then needs it passed explicitly.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

from remoteenv.wire.delays.delay_specs import SECONDS, DelaySpec, as_delay, delay_from_wire
from remoteenv.wire.wire_errors import ProtocolError

#: Arguments about where and how a sim runs, not what it simulates: never recorded, free in a twin.
PROCESS_KWARGS = frozenset(
    {
        "transport",
        "timeout",
        "startup_timeout",
        "call_timeouts",
        "restart_on_failure",
        "max_restarts",
        "bind_host",
        "curve",
        "launcher",
        "attach",
        "seed",
    }
)
#: A vector env's own arguments (a world's twin is a single env).
VECTOR_KWARGS = frozenset({"num_envs", "envs_per_process", "autoreset_mode", "batch_size", "vectorization_mode"})
#: Real-time settings, recorded from the sim's handshake (and the time limit) rather than from arguments.
REAL_TIME_KWARGS = frozenset({"real_time", "real_time_factor", "real_time_mode", "link_delay", "max_episode_steps"})
#: The key a delay spec's wire map is stored under among the recorded kwargs.
DELAY_TAG = "remoteenv_delay_spec"
#: Largest recorded kwargs, as JSON (bytes).
MAX_KWARGS_JSON = 64 * 1024


@dataclass
class RecordedEnv:
    """The env of a recording (see the module docs).

    Attributes:
        kwargs: the ``gym.make`` keyword arguments that shape the world,
            JSON values (a delay spec as ``{DELAY_TAG: wire map}``).
        max_episode_steps: the time limit in steps (decisions); None: none.
        real_time_factor: simulated seconds per wall second.
        link_delay: the emulated link's spec as its wire map (None: no link).
        unrecorded: names of arguments that could not be written down.
    """

    kwargs: dict[str, Any] = field(default_factory=dict)
    max_episode_steps: int | None = None
    real_time_factor: float = 1.0
    link_delay: dict[str, Any] | None = None
    unrecorded: list[str] = field(default_factory=list)

    @classmethod
    def from_env(cls, env: Any) -> RecordedEnv:
        """Read off a live real-time env (single, or a :class:`remoteenv.RemoteVectorEnv`)."""
        unwrapped = getattr(env, "unwrapped", env)
        _, init_kwargs = unwrapped.__dict__.get("_init_args", ((), {}))
        spec = getattr(env, "spec", None)
        registered = _registered_kwargs(getattr(spec, "id", None))
        kwargs: dict[str, Any] = {}
        unrecorded: list[str] = []
        for key, value in init_kwargs.items():
            if key in PROCESS_KWARGS or key in VECTOR_KWARGS or key in REAL_TIME_KWARGS:
                continue
            if key in registered and _same(registered[key], value):
                continue  # the id's own (e.g. its scene path on this machine)
            encoded = _encode(value)
            if encoded is _UNWRITABLE:
                unrecorded.append(key)
            else:
                kwargs[key] = encoded
        try:
            stepping = dict(unwrapped.handshake["stepping"])
        except (AttributeError, KeyError, TypeError):
            stepping = {}
        return cls(
            kwargs=kwargs,
            max_episode_steps=_time_limit(env, unwrapped),
            real_time_factor=float(stepping.get("real_time_factor", init_kwargs.get("real_time_factor", 1.0))),
            link_delay=stepping.get("link_delay_spec"),
            unrecorded=unrecorded,
        )

    def make_kwargs(self) -> dict[str, Any]:
        """The ``gym.make`` arguments that rebuild this env (besides ``real_time``,
        ``real_time_mode`` and the time limit): the recorded kwargs decoded,
        ``real_time_factor`` and ``link_delay``."""
        out = {key: _decode(value) for key, value in self.kwargs.items()}
        out["real_time_factor"] = self.real_time_factor
        if self.link_delay is not None:
            out["link_delay"] = delay_from_wire(self.link_delay)
        return out

    def check_explicit(self, explicit: dict[str, Any], what: str) -> None:
        """Raise a one-line ValueError naming the first of ``explicit``'s arguments
        that contradicts this recording (``what``: the recording, for the message)."""
        recorded = self.make_kwargs()
        for key, value in explicit.items():
            if key in PROCESS_KWARGS or key in self.unrecorded:
                continue
            if key == "real_time" and value is True:
                continue
            if key not in recorded:
                raise ValueError(
                    f"make_twin: {key}={_short(value)} is not in {what}, whose run used the default: "
                    "drop it (the twin rebuilds the recorded env)"
                )
            if not _same(recorded[key], value):
                raise ValueError(
                    f"make_twin: {key}={_short(value)} contradicts {what} ({key}={_short(recorded[key])}): "
                    "drop it or pass the recorded value"
                )

    def to_document(self) -> dict[str, Any]:
        return {
            "kwargs": self.kwargs,
            "max_episode_steps": self.max_episode_steps,
            "real_time_factor": self.real_time_factor,
            "link_delay": self.link_delay,
            "unrecorded": list(self.unrecorded),
        }

    @classmethod
    def from_document(cls, doc: Any, what: str) -> RecordedEnv:
        """Parse :meth:`to_document`'s map from a file (hostile: every field checked)."""
        if not isinstance(doc, dict):
            raise ValueError(f"{what}: 'env' must be a map")
        kwargs = doc.get("kwargs")
        if not isinstance(kwargs, dict) or not all(isinstance(k, str) for k in kwargs):
            raise ValueError(f"{what}: env kwargs must be a map with string keys")
        if len(json.dumps(kwargs)) > MAX_KWARGS_JSON:
            raise ValueError(f"{what}: env kwargs are larger than {MAX_KWARGS_JSON} bytes")
        limit = doc.get("max_episode_steps")
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int)):
            raise ValueError(f"{what}: max_episode_steps must be an int or null")
        factor = doc.get("real_time_factor")
        if (
            isinstance(factor, bool)
            or not isinstance(factor, (int, float))
            or not (math.isfinite(factor) and factor > 0)
        ):
            raise ValueError(f"{what}: real_time_factor must be a number > 0")
        link = doc.get("link_delay")
        try:
            for value in kwargs.values():
                _decode(value)
            if link is not None:
                as_delay(delay_from_wire(link), SECONDS)
        except (ProtocolError, ValueError) as exc:
            raise ValueError(f"{what}: {str(exc)[:200]}") from None
        unrecorded = doc.get("unrecorded", [])
        if not isinstance(unrecorded, list) or not all(isinstance(u, str) for u in unrecorded):
            raise ValueError(f"{what}: 'unrecorded' must be a list of names")
        return cls(kwargs, limit, float(factor), link, [u[:100] for u in unrecorded[:100]])


_UNWRITABLE = object()


def _encode(value: Any) -> Any:
    """``value`` as JSON (a delay spec tagged), or :data:`_UNWRITABLE`."""
    if isinstance(value, DelaySpec):
        return {DELAY_TAG: value.to_wire()}
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        return _UNWRITABLE
    return json.loads(text)


def _decode(value: Any) -> Any:
    if isinstance(value, dict) and set(value) == {DELAY_TAG}:
        return delay_from_wire(value[DELAY_TAG])
    return value


def _same(a: Any, b: Any) -> bool:
    """Equal as a twin would see them: delay specs (or a number standing for a
    constant one) by their wire form, other values by their JSON form."""
    if isinstance(a, DelaySpec) or isinstance(b, DelaySpec):
        try:
            unit = a.unit if isinstance(a, DelaySpec) else b.unit
            return bool(as_delay(a, unit).to_wire() == as_delay(b, unit).to_wire())
        except (TypeError, ValueError):
            return False
    encoded_a, encoded_b = _encode(a), _encode(b)
    return encoded_a is not _UNWRITABLE and encoded_a == encoded_b


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _registered_kwargs(env_id: str | None) -> dict[str, Any]:
    if not env_id:
        return {}
    try:
        return dict(gym.spec(env_id).kwargs)
    except gym.error.Error:
        return {}


def _time_limit(env: Any, unwrapped: Any) -> int | None:
    """The steps a ``TimeLimit`` in ``env``'s wrappers allows, or a vector env's own limit."""
    if hasattr(unwrapped, "num_envs"):
        limit = getattr(unwrapped, "max_episode_steps", None)
        return None if limit is None else int(limit)
    layer = env
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, gym.wrappers.TimeLimit):
            return int(layer._max_episode_steps)
        layer = layer.env
    return None


__all__ = ["DELAY_TAG", "PROCESS_KWARGS", "REAL_TIME_KWARGS", "RecordedEnv", "VECTOR_KWARGS"]
