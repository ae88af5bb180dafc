"""The ``handshake`` exchange, both directions: the request and the reply parsed
into a :class:`Handshake` (part of the spec in :mod:`remoteenv.wire.protocol`).

Any client of the protocol parses the reply here (the agent's envs and the
compliance checker alike), so a server's reply is judged by one set of rules:
the fields an env needs (``protocol``, both spaces, ``metadata`` with
``render_modes``, ``render_fps`` and ``dt``) must be present and well typed;
the others default when absent (``env_id``/``pid`` nil, ``instance`` 0,
``num_worlds`` 1, ``stepping`` lock-step without delay, ``commands`` as the
spec says a client should assume, see :meth:`Handshake.offers`).

The reply's counts are bounded before anything is built from them: the
spaces as :func:`~remoteenv.wire.codec.spaces.space_from_wire` says, and
:func:`worlds_problem`: ``num_worlds`` at most
:data:`~remoteenv.wire.codec.frame_limits.MAX_WORLDS`, with every world's
observation fitting in one frame together (a batch reply carries them all).

Both processes use it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from gymnasium import spaces

from remoteenv.wire.codec.frame_limits import MAX_MESSAGE_BYTES, MAX_WORLDS
from remoteenv.wire.codec.spaces import space_from_wire, value_nbytes
from remoteenv.wire.protocol import PROTOCOL_VERSION
from remoteenv.wire.run_options.real_time_modes import ELASTIC, REAL_TIME_MODES
from remoteenv.wire.wire_errors import ProtocolError, short_repr

#: ``stepping["mode"]`` of a sim that advances only when asked.
LOCK_STEP = "lock_step"
#: ``stepping["mode"]`` of a sim that runs on a paced wall clock.
REAL_TIME = "real_time"
#: The largest ``metadata["world_cost_s"]`` a reply may state (seconds).
MAX_WORLD_COST_S = 60.0
#: The most ``metadata["physics_threads"]`` a reply may state.
MAX_PHYSICS_THREADS = 4096
#: Commands every server answers.
CORE_COMMANDS = frozenset({"handshake", "reset", "step", "render", "close"})
#: Commands a server without a ``commands`` list answers in lock-step only...
LOCK_STEP_COMMANDS = frozenset({"reset_batch", "step_batch"})
#: ... and in real time only.
REAL_TIME_COMMANDS = frozenset({"timing"})


def handshake_request(version: int = PROTOCOL_VERSION, world_cost: bool = False, probe: bool = False) -> dict[str, Any]:
    """The arguments of a ``handshake`` request (without ``seq``/``cmd``);
    ``world_cost``: ask the sim to measure one world's whole tick (``metadata["world_cost_s"]``);
    ``probe`` (with it): the sim will be closed after the handshake, so it may
    measure on its own world 0 instead of a scratch one."""
    request: dict[str, Any] = {"protocol": version}
    if world_cost:
        request["world_cost"] = True
        if probe:
            request["probe"] = True
    return request


@dataclass(frozen=True)
class Handshake:
    """A sim's answer to ``handshake``. Times are in simulated seconds.

    Mapping access (``hs["metadata"]["dt"]``) reads the reply as received, for
    code written against the plain map.
    """

    protocol: int
    observation_space: spaces.Space
    action_space: spaces.Space
    render_modes: tuple[str, ...]
    #: Frames per second a viewer should show (None: unspecified).
    render_fps: float | None
    #: Simulated seconds per env step.
    dt: float
    env_id: str | None = None
    instance: int = 0
    pid: int | None = None
    num_worlds: int = 1
    #: Simulated seconds per physics substep, if the server says.
    timestep: float | None = None
    #: Physics substeps per env step, if the server says.
    frame_skip: int | None = None
    #: ``LOCK_STEP`` or ``REAL_TIME``.
    stepping_mode: str = LOCK_STEP
    #: Lock-step: ticks by which an action's effect is delayed (the largest, for a random model).
    action_delay: int = 0
    #: Lock-step: ticks by which observations are delayed (the largest).
    obs_delay: int = 0
    #: Real time: simulated seconds per wall-clock second (None in lock-step).
    real_time_factor: float | None = None
    #: Real time: the regime (``"elastic"`` or ``"fixed_step"``; None in lock-step).
    real_time_mode: str | None = None
    #: Every command the server answers, if its reply lists them.
    commands: frozenset[str] | None = None
    #: Wall seconds one world's control tick costs the server on one thread
    #: (physics and camera rendering), if it says: a layout hint.
    world_cost_s: float | None = None
    #: Lock-step: threads the server steps its worlds' physics on, if it says.
    physics_threads: int | None = None
    #: Lock-step: whether the server steps its worlds as one batch through the
    #: scene's stacked hooks (its Python once per tick, not per world), if it says.
    stacked_hooks: bool | None = None
    #: The reply map as received.
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def real_time(self) -> bool:
        return self.stepping_mode == REAL_TIME

    @property
    def timed_steps(self) -> bool:
        """True when step replies carry timing keys (real time, or a lock-step delay)."""
        return self.real_time or self.action_delay > 0 or self.obs_delay > 0

    def offers(self, cmd: str) -> bool:
        """Whether the server answers ``cmd``: as its ``commands`` list says, or
        without one, the core commands plus the batch commands in lock-step and
        ``timing`` in real time."""
        if self.commands is not None:
            return cmd in self.commands
        if cmd in CORE_COMMANDS:
            return True
        return cmd in (REAL_TIME_COMMANDS if self.real_time else LOCK_STEP_COMMANDS)

    def __getitem__(self, key: str) -> Any:
        return self.raw[key]


def _need(doc: Mapping[str, Any], key: str, types: type | tuple[type, ...], where: str) -> Any:
    if key not in doc:
        raise ProtocolError(f"handshake reply lacks {where}{key!r}")
    return _typed(doc, key, types, where)


def _typed(doc: Mapping[str, Any], key: str, types: type | tuple[type, ...], where: str) -> Any:
    """``doc[key]`` checked against ``types``, or None when absent or nil."""
    value = doc.get(key)
    if value is None:
        return None
    if isinstance(value, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
        raise ProtocolError(f"handshake {where}{key!r} must not be a bool, got {value!r}")
    if not isinstance(value, types):
        raise ProtocolError(f"handshake {where}{key!r} has the wrong type: {short_repr(value)}")
    return value


class BatchTooLarge(ProtocolError):
    """A sim hosts more worlds than one batch reply can carry the observations
    of; :attr:`worlds_that_fit` says how many would (0: not even one)."""

    def __init__(self, message: str, worlds_that_fit: int) -> None:
        super().__init__(message)
        self.worlds_that_fit = worlds_that_fit


def worlds_that_fit(observation_space: spaces.Space) -> int:
    """Most worlds whose observations one batch reply carries (the frame limit)."""
    return MAX_MESSAGE_BYTES // max(1, value_nbytes(observation_space))


def worlds_problem(num_worlds: Any, observation_space: spaces.Space) -> str | None:
    """What is wrong with a handshake's ``num_worlds`` for its observation space, if anything."""
    if not isinstance(num_worlds, int) or isinstance(num_worlds, bool) or not 1 <= num_worlds <= MAX_WORLDS:
        return f"'num_worlds' must be an int in 1..{MAX_WORLDS}, got {short_repr(num_worlds)}"
    batch = num_worlds * value_nbytes(observation_space)
    if batch > MAX_MESSAGE_BYTES:
        fit = worlds_that_fit(observation_space)
        return (
            f"{num_worlds} worlds' observations take {batch} bytes, above the frame limit of "
            f"{MAX_MESSAGE_BYTES} bytes: no batch reply could carry them; "
            + (f"at most {fit} of them fit a reply (envs_per_process={fit})" if fit else "not even one fits a reply")
        )
    return None


def _space(reply: Mapping[str, Any], key: str) -> spaces.Space:
    try:
        return space_from_wire(_need(reply, key, dict, ""))
    except ProtocolError as exc:
        raise ProtocolError(f"handshake {key!r} is a malformed space: {exc}") from None


def _real_time_mode(stepping: Mapping[str, Any]) -> str | None:
    """The regime of a real-time handshake (a server that does not say runs the elastic one)."""
    if stepping.get("mode") != REAL_TIME:
        return None
    mode = _typed(stepping, "real_time_mode", str, "stepping ") or ELASTIC
    if mode not in REAL_TIME_MODES:
        raise ProtocolError(f"handshake stepping 'real_time_mode' is unknown: {short_repr(mode)}")
    return mode


def parse_handshake(reply: Mapping[str, Any], expected_version: int = PROTOCOL_VERSION) -> Handshake:
    """Check a ``handshake`` reply and parse it; :class:`ProtocolError` names what is wrong."""
    if not isinstance(reply, Mapping):
        raise ProtocolError(f"a handshake reply must be a map, got {type(reply).__name__}")
    version = _need(reply, "protocol", int, "")
    if version != expected_version:
        raise ProtocolError(
            f"the sim answered the handshake with protocol version {version}; this client speaks {expected_version}"
        )
    meta = _need(reply, "metadata", dict, "")
    stepping = _typed(reply, "stepping", dict, "") or {}
    obs_space = _space(reply, "observation_space")
    act_space = _space(reply, "action_space")
    num_worlds = _typed(reply, "num_worlds", int, "")
    num_worlds = 1 if num_worlds is None else num_worlds
    problem = worlds_problem(num_worlds, obs_space)
    if problem is not None:
        fit = worlds_that_fit(obs_space)
        if isinstance(num_worlds, int) and 1 <= num_worlds <= MAX_WORLDS and fit < num_worlds:
            raise BatchTooLarge(f"handshake {problem}", fit)
        raise ProtocolError(f"handshake {problem}")
    render_modes = _need(meta, "render_modes", list, "metadata ")
    if not all(isinstance(m, str) for m in render_modes):
        raise ProtocolError(f"handshake metadata 'render_modes' must be strings: {short_repr(render_modes)}")
    fps = _typed(meta, "render_fps", (int, float), "metadata ")
    timestep = _typed(meta, "timestep", (int, float), "metadata ")
    rtf = _typed(stepping, "real_time_factor", (int, float), "stepping ")
    cost = _typed(meta, "world_cost_s", (int, float), "metadata ")
    if cost is not None and not 0 <= cost <= MAX_WORLD_COST_S:
        raise ProtocolError(f"handshake metadata 'world_cost_s' must be 0..{MAX_WORLD_COST_S} s, got {cost!r}")
    threads = _typed(meta, "physics_threads", int, "metadata ")
    if threads is not None and not 1 <= threads <= MAX_PHYSICS_THREADS:
        raise ProtocolError(f"handshake metadata 'physics_threads' must be 1..{MAX_PHYSICS_THREADS}, got {threads!r}")
    stacked = _typed(meta, "stacked_hooks", bool, "metadata ")
    commands = _typed(reply, "commands", list, "")
    if commands is not None and not all(isinstance(c, str) for c in commands):
        raise ProtocolError(f"handshake 'commands' must be strings: {short_repr(commands)}")
    return Handshake(
        protocol=version,
        observation_space=obs_space,
        action_space=act_space,
        render_modes=tuple(render_modes),
        render_fps=fps,
        dt=float(_need(meta, "dt", (int, float), "metadata ")),
        env_id=_typed(reply, "env_id", str, ""),
        instance=_typed(reply, "instance", int, "") or 0,
        pid=_typed(reply, "pid", int, ""),
        num_worlds=num_worlds,
        timestep=None if timestep is None else float(timestep),
        frame_skip=_typed(meta, "frame_skip", int, "metadata "),
        stepping_mode=_typed(stepping, "mode", str, "stepping ") or LOCK_STEP,
        action_delay=_typed(stepping, "action_delay", int, "stepping ") or 0,
        obs_delay=_typed(stepping, "obs_delay", int, "stepping ") or 0,
        real_time_factor=None if rtf is None else float(rtf),
        real_time_mode=_real_time_mode(stepping),
        commands=None if commands is None else frozenset(commands),
        world_cost_s=None if cost is None else float(cost),
        physics_threads=threads,
        stacked_hooks=stacked,
        raw=reply,
    )


__all__ = [
    "BatchTooLarge",
    "CORE_COMMANDS",
    "LOCK_STEP",
    "LOCK_STEP_COMMANDS",
    "REAL_TIME",
    "REAL_TIME_COMMANDS",
    "Handshake",
    "handshake_request",
    "parse_handshake",
    "worlds_problem",
    "worlds_that_fit",
]
