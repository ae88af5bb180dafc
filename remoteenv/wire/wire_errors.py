"""Error kinds of the wire and the exceptions the shared checks raise.

An error reply carries one of :data:`ERROR_KINDS` (see the spec in
:mod:`remoteenv.wire.protocol`); the agent side turns each kind into its own
exception class (:mod:`remoteenv.agent.errors`).
"""

from __future__ import annotations

import reprlib

#: A malformed request, unknown command or version mismatch.
PROTOCOL = "protocol"
#: An action outside the action space.
INVALID_ACTION = "invalid_action"
#: The scene's env code raised.
SCENE = "scene"
#: A request that does not fit the world's state (e.g. step before reset).
STATE = "state"
#: ``get_attr``/``set_attr``/``call`` named an attribute the scene lacks, or a private one.
ATTRIBUTE = "attribute"
#: A value that cannot cross the wire (e.g. an ``MjModel`` asked for by ``get_attr``).
UNSENDABLE = "unsendable"
#: The kinds an error reply may carry.
ERROR_KINDS = frozenset({PROTOCOL, INVALID_ACTION, SCENE, STATE, ATTRIBUTE, UNSENDABLE})

#: The words of a ``state`` refusal because another connection drives the world
#: (see "Drivers" in :mod:`remoteenv.wire.protocol`); a client taking a world over
#: retries such a refusal for up to ``DRIVER_RELEASE_GRACE_S``.
ANOTHER_DRIVER = "is driven by another connection"


def refused_for_another_driver(reply: object) -> bool:
    """Whether ``reply`` is a ``state`` error that names another driver of the world."""
    if not isinstance(reply, dict) or reply.get("ok") is not False:
        return False
    error = reply.get("error")
    return (
        isinstance(error, dict)
        and error.get("kind") == STATE
        and isinstance(error.get("message"), str)
        and ANOTHER_DRIVER in error["message"]
    )


#: Exit status of a sim process whose env factory refused its keyword
#: arguments; it also writes :data:`SCENE_ARGS_MARKER` and the reason to
#: stderr, which the launcher raises as a ``TypeError`` (see ``run_scene``).
EXIT_SCENE_ARGS = 3
SCENE_ARGS_MARKER = "remoteenv: the scene's env factory refused its keyword arguments:"
#: Exit status of a sim process whose worlds would not fit in memory; it writes
#: :data:`RESOURCES_MARKER` and the reason (one line, with the figures) to
#: stderr, which the launcher raises as a ``LimitError``.
EXIT_RESOURCES = 4
RESOURCES_MARKER = "remoteenv: the sim refused to build its worlds:"

#: Longest text of an error message built from a request's content (characters).
MAX_ECHO_CHARS = 200


class ProtocolError(ValueError):
    """A frame or field does not follow the spec of :mod:`remoteenv.wire.protocol`."""


class InvalidAction(ValueError):
    """An action is not in the action space; the message names the space and the value."""


class _BoundedRepr(reprlib.Repr):
    """A ``repr`` whose cost is bounded by its output, whatever the input's size."""

    def repr_bytes(self, value: bytes, level: int) -> str:
        head = repr(value[: self.maxstring])
        return head if len(value) <= self.maxstring else f"{head}...({len(value)} bytes)"

    repr_bytearray = repr_bytes

    def repr_int(self, value: int, level: int) -> str:
        # repr() of a huge int costs time quadratic in its digits (and may raise).
        if value.bit_length() > 4 * self.maxlong:
            return f"<int of {value.bit_length()} bits>"
        return super().repr_int(value, level)

    def repr_instance(self, value: object, level: int) -> str:
        # numpy arrays summarise themselves; other objects are named, not printed.
        import numpy as np

        if value is None or isinstance(value, (bool, float, complex, np.generic)):
            return repr(value)

        if isinstance(value, np.ndarray):
            with np.printoptions(threshold=16, edgeitems=3):
                return repr(value)
        return f"<{type(value).__name__}>"


_bounded = _BoundedRepr()
_bounded.maxstring = MAX_ECHO_CHARS
_bounded.maxother = MAX_ECHO_CHARS
_bounded.maxlong = 60


def short_repr(value: object, limit: int = MAX_ECHO_CHARS) -> str:
    """A ``repr`` of ``value`` of at most ``limit`` characters, built without
    rendering all of a large input first (for messages that echo input)."""
    text = _bounded.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
