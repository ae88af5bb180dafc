"""Argument types shared by the commands: numbers are checked when parsed,
before a command starts any work, and refused with a message naming the rule.

Each is an ``argparse`` ``type=``: it raises ``argparse.ArgumentTypeError``,
which argparse reports as ``argument --name: <message>`` (exit status 2).

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
from typing import Any


def positive_int(text: str) -> int:
    """An integer >= 1 (a count of steps, episodes, instances, worlds)."""
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text[:80]!r}")
    return value


def non_negative_int(text: str) -> int:
    """An integer >= 0 (an index, a delay in ticks)."""
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text[:80]!r}")
    return value


#: Seeds the wire carries: Gymnasium takes any integer >= 0, the wire's integers end below 2**64.
MAX_SEED = 2**64 - 1


def seed_int(text: str) -> int:
    """A reset seed: an integer in ``0..2**64 - 1``."""
    value = _int(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(
            f"must be an integer in 0..2**64-1 (a seed the wire carries), got {text[:80]!r}"
        )
    return value


#: Longest timeout (seconds) a command takes: 11.5 days; beyond it the
#: millisecond counts handed to ZeroMQ's poll would overflow sooner or later.
MAX_SECONDS = 1e6


def positive_seconds(text: str) -> float:
    """A number of seconds in ``(0, MAX_SECONDS]`` (``inf``, ``nan``, 0 and negatives are refused)."""
    value = _positive_finite(text, f"a number of seconds > 0 and <= {MAX_SECONDS:.0f}")
    if value > MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0 and <= {MAX_SECONDS:.0f}, got {text[:80]!r}")
    return value


def positive_factor(text: str) -> float:
    """A finite number > 0 (e.g. a real-time factor)."""
    return _positive_finite(text, "a finite number > 0")


def check_can_write(path: str, what: str) -> None:
    """Exit with a clear message unless a file can be created at ``path``: its
    directory exists and takes a new file, and ``path`` is not a directory.

    Run before a command starts work whose results go to ``path``, so an
    unwritable path fails at once instead of after the work.
    """
    if os.path.isdir(path):
        raise SystemExit(f"{what} {path!r} is a directory; name a file")
    directory = os.path.dirname(os.path.abspath(path))
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".remoteenv-probe-")
    except OSError as exc:
        raise SystemExit(f"cannot write {what} {path!r}: {exc.strerror or exc} (in {directory!r})") from None
    os.close(fd)
    os.unlink(probe)


def json_map(text: str, option: str) -> dict[str, Any]:
    """The JSON map ``text`` given to ``option``; exits with a clear message otherwise."""
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise SystemExit(f"{option} must be a JSON map, got {text[:80]!r} ({type(exc).__name__})") from None
    if not isinstance(value, dict):
        raise SystemExit(f"{option} must be a JSON map, got {text[:80]!r}")
    return value


def non_negative_number(text: str) -> float:
    """A finite number >= 0 (e.g. a think time in milliseconds)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text[:80]!r}")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text[:80]!r}") from None


def _positive_finite(text: str, rule: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {rule}, got {text[:80]!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be {rule}, got {text[:80]!r}")
    return value


__all__ = [
    "MAX_SECONDS",
    "check_can_write",
    "json_map",
    "non_negative_int",
    "non_negative_number",
    "positive_factor",
    "positive_int",
    "positive_seconds",
]
