"""The handshake reply, judged against the spec and parsed for the other checks.

The spec (:mod:`remoteenv.wire.protocol`, ``handshake``) lists the reply's
fields; their types are checked here. One field is an optional extension the
compliance suite understands: ``"commands"``, a list of the command names the
server answers. Without it, batch commands are taken to exist exactly when
``stepping.mode`` is ``"lock_step"`` and ``timing`` when it is
``"real_time"`` (what the spec says today); with it, the list decides, so a
lock-step server without batch commands (a robot bridge) can say so.

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from gymnasium import spaces

from remoteenv.compliance.failures import CheckFailed
from remoteenv.compliance.values import is_int, is_number, type_name
from remoteenv.wire.codec.frame_limits import MAX_WORLDS
from remoteenv.wire.codec.spaces import space_from_wire
from remoteenv.wire.messages.handshake import LOCK_STEP, REAL_TIME, worlds_problem
from remoteenv.wire.wire_errors import short_repr

#: Commands every server answers.
CORE_COMMANDS = ("handshake", "reset", "step", "render", "close")
#: Commands of lock-step servers (unless a ``commands`` list leaves them out).
BATCH_COMMANDS = ("reset_batch", "step_batch")
STEPPING_MODES = (LOCK_STEP, REAL_TIME)


@dataclass(frozen=True)
class Handshake:
    """A handshake reply that passed :func:`handshake_problems`."""

    reply: dict[str, Any]
    protocol: int
    env_id: str
    num_worlds: int
    observation_space: spaces.Space
    action_space: spaces.Space
    #: ``stepping.mode``: ``"lock_step"`` or ``"real_time"``.
    mode: str
    #: The advertised ``commands``, or None if the server sends no such list.
    commands: frozenset[str] | None = None

    def offered(self) -> frozenset[str]:
        """The commands the server offers: its ``commands`` list, or those its stepping mode implies."""
        if self.commands is not None:
            return self.commands
        optional = BATCH_COMMANDS if self.mode == LOCK_STEP else ("timing",)
        return frozenset((*CORE_COMMANDS, *optional))

    def lacks(self, *names: str) -> str | None:
        """None if the server offers every command in ``names``, else why not (for skip reasons)."""
        missing = [n for n in names if n not in self.offered()]
        if not missing:
            return None
        if self.commands is not None:
            return f"the server's handshake lists commands without {missing}"
        return f"a {self.mode} server without a 'commands' list in its handshake does not offer {missing}"


def _space(reply: dict[str, Any], key: str, problems: list[str]) -> spaces.Space | None:
    desc = reply.get(key)
    if not isinstance(desc, dict):
        problems.append(f"{key} must be a space map, got {type_name(desc)}")
        return None
    try:
        return space_from_wire(desc)
    except Exception as exc:  # KeyError, ValueError, ProtocolError... from an off-spec map
        problems.append(
            f"{key} {short_repr(desc)} is not a space map of the spec ({type(exc).__name__}: {short_repr(str(exc))})"
        )
        return None


def handshake_problems(reply: dict[str, Any]) -> list[str]:
    """Everything wrong with the fields of an ``ok`` handshake reply (empty: none)."""
    problems: list[str] = []
    for key, test, want in (
        ("protocol", is_int, "an int"),
        ("env_id", lambda v: isinstance(v, str), "a str"),
        ("instance", is_int, "an int"),
        ("pid", lambda v: v is None or is_int(v), "an int or nil"),
        ("num_worlds", lambda v: is_int(v) and 1 <= v <= MAX_WORLDS, f"an int in 1..{MAX_WORLDS}"),
    ):
        if not test(reply.get(key)):
            problems.append(f"{key} must be {want}, got {short_repr(reply.get(key))}")
    obs_space = _space(reply, "observation_space", problems)
    _space(reply, "action_space", problems)
    if obs_space is not None and not problems:
        problem = worlds_problem(reply.get("num_worlds"), obs_space)
        if problem is not None:
            problems.append(problem)
    meta = reply.get("metadata")
    if not isinstance(meta, dict):
        problems.append(f"metadata must be a map, got {type_name(meta)}")
    else:
        modes = meta.get("render_modes")
        if not (isinstance(modes, list) and all(isinstance(m, str) for m in modes)):
            problems.append(f"metadata.render_modes must be a list of str, got {short_repr(modes)}")
        for key, test, want in (
            ("render_fps", lambda v: v is None or (is_number(v) and v > 0), "a number > 0 or nil"),
            ("dt", lambda v: is_number(v) and v > 0, "a number of seconds > 0"),
            ("timestep", lambda v: is_number(v) and v > 0, "a number of seconds > 0"),
            ("frame_skip", lambda v: is_int(v) and v >= 1, "an int >= 1"),
        ):
            if not test(meta.get(key)):
                problems.append(f"metadata.{key} must be {want}, got {short_repr(meta.get(key))}")
    stepping = reply.get("stepping")
    if not isinstance(stepping, dict) or stepping.get("mode") not in STEPPING_MODES:
        problems.append(
            f"stepping must be a map whose mode is one of {list(STEPPING_MODES)}, got {short_repr(stepping)}"
        )
    commands = reply.get("commands")
    if commands is not None:
        if not (isinstance(commands, list) and all(isinstance(c, str) for c in commands)):
            problems.append(f"commands (optional) must be a list of str, got {short_repr(commands)}")
        elif missing := [c for c in CORE_COMMANDS if c not in commands]:
            problems.append(
                f"commands lists {short_repr(commands)} but leaves out {missing}, which every server answers"
            )
    return problems


def parse_handshake(reply: dict[str, Any]) -> Handshake:
    """The parsed handshake; raises :class:`CheckFailed` naming every problem."""
    problems = handshake_problems(reply)
    if problems:
        raise CheckFailed("handshake reply: " + "; ".join(problems))
    commands = reply.get("commands")
    return Handshake(
        reply=reply,
        protocol=reply["protocol"],
        env_id=reply["env_id"],
        num_worlds=reply["num_worlds"],
        observation_space=space_from_wire(reply["observation_space"]),
        action_space=space_from_wire(reply["action_space"]),
        mode=reply["stepping"]["mode"],
        commands=None if commands is None else frozenset(commands),
    )


__all__ = ["BATCH_COMMANDS", "CORE_COMMANDS", "STEPPING_MODES", "Handshake", "handshake_problems", "parse_handshake"]
