"""The checks a request's fields pass before a command acts on them.

Runs in the sim process. Single and batch commands share these, so a field
is accepted or refused by the same rule whichever command carries it. Each
check raises :class:`RequestError`, which the server turns into a typed error
reply; messages echo at most a bounded repr of the offending value. Actions
are checked by :mod:`remoteenv.wire.messages.action_rules` (the agent applies the same
rules), whose :class:`~remoteenv.wire.wire_errors.InvalidAction` the server maps
to the ``invalid_action`` kind.
"""

from __future__ import annotations

from typing import Any

from remoteenv.wire.wire_errors import ANOTHER_DRIVER, PROTOCOL, STATE, short_repr


class RequestError(Exception):
    """A request the server refuses; becomes an error reply of ``kind``."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def world_index(msg: dict[str, Any], num_worlds: int) -> int:
    """The request's ``world`` (default 0), one of the ``num_worlds`` this process hosts."""
    world = msg.get("world", 0)
    if not _is_int(world) or not 0 <= world < num_worlds:
        raise RequestError(PROTOCOL, f"world {short_repr(world)} out of range; this process hosts {num_worlds}")
    return world


def world_list(worlds: Any, num_worlds: int) -> list[int]:
    """A non-empty list of world indices, each in ``[0, num_worlds)``."""
    if not isinstance(worlds, list) or not worlds or not all(_is_int(w) and 0 <= w < num_worlds for w in worlds):
        raise RequestError(
            PROTOCOL, f"worlds must be a non-empty list of ints in [0, {num_worlds}), got {short_repr(worlds)}"
        )
    return worlds


def seed_value(seed: Any) -> int | None:
    """A reset's seed: a non-negative int, or None to continue the world's RNG stream."""
    if seed is not None and (not _is_int(seed) or seed < 0):
        raise RequestError(PROTOCOL, f"seed must be a non-negative int or nil, got {short_repr(seed)}")
    return seed


def seed_list(seeds: Any, count: int) -> list[int | None]:
    """One seed (or None) per world of a batch reset; None for the whole list means no seeds."""
    if seeds is None:
        return [None] * count
    if (
        not isinstance(seeds, list)
        or len(seeds) != count
        or not all(s is None or (_is_int(s) and s >= 0) for s in seeds)
    ):
        raise RequestError(PROTOCOL, "seeds must be nil or a list (one per world) of non-negative ints or nil")
    return seeds


def options_value(options: Any) -> dict[str, Any] | None:
    """A reset's options: a map or None (its content is the scene's business)."""
    if options is not None and not isinstance(options, dict):
        raise RequestError(PROTOCOL, f"options must be a map or nil, got {type(options).__name__}")
    return options


def protocol_version(value: Any, speaks: int, instance: int) -> int:
    """The handshake's ``protocol``: exactly the int ``speaks`` (no bool, float or array)."""
    if not _is_int(value) or value != speaks:
        raise RequestError(
            PROTOCOL,
            f"protocol version mismatch: agent speaks {short_repr(value)}, sim instance {instance} speaks {speaks}",
        )
    return value


def require_driver(owner: Any, sender: Any, world: int, instance: int, cmd: str) -> None:
    """Refuse ``cmd`` on ``world`` from ``sender`` when another connection (``owner``) drives it.

    ``owner`` and ``sender`` are ``(channel, routing id)`` pairs; ``owner`` None means nobody does yet.
    """
    if owner is not None and owner != sender:
        raise RequestError(
            STATE,
            f"'{cmd}' refused: world {world} of sim instance {instance} {ANOTHER_DRIVER} "
            "(the launching agent, or the one that reset it first, until its connection "
            "ends); only that one may reset, step, pause, resume or close it. Other commands "
            "(handshake, render, timing, attributes) are open to all.",
        )


def require_reset(has_reset: bool, world: int, instance: int) -> None:
    """Refuse to step ``world`` of sim ``instance`` before its first reset."""
    if not has_reset:
        raise RequestError(STATE, f"step before reset on world {world} of instance {instance}")


__all__ = [
    "RequestError",
    "options_value",
    "protocol_version",
    "require_driver",
    "require_reset",
    "seed_list",
    "seed_value",
    "world_index",
    "world_list",
]
