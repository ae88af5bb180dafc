"""How a check says that a server broke the spec, or that the check does not apply. Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes)."""

from __future__ import annotations


class CheckFailed(AssertionError):
    """The server broke the spec; the message says how."""


class CheckSkipped(Exception):
    """The check does not apply to this server; the message says why."""


def fail_unless(condition: object, message: str) -> None:
    """Raise :class:`CheckFailed` with ``message`` if ``condition`` is false."""
    if not condition:
        raise CheckFailed(message)


__all__ = ["CheckFailed", "CheckSkipped", "fail_unless"]
