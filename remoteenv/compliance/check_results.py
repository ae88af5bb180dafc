"""What a compliance check is and what it reports.

A check is a named function that drives one server through a fresh
connection (:class:`~remoteenv.compliance.probe.Probe`) and either returns
(pass, with an optional note), raises
:class:`~remoteenv.compliance.failures.CheckFailed` (fail) or raises
:class:`~remoteenv.compliance.failures.CheckSkipped` (skip: the server does
not offer what the check needs).

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from remoteenv.compliance.probe import Probe

PASS = "pass"
FAIL = "fail"
SKIP = "skip"


@dataclass(frozen=True)
class Check:
    """One compliance check: ``run(probe)`` passes by returning (optionally a note)."""

    name: str
    description: str
    run: Callable[[Probe], str | None]


@dataclass(frozen=True)
class Result:
    """The outcome of one check against one server."""

    check: Check
    status: str
    reason: str = ""
    #: Wall seconds the check took.
    seconds: float = 0.0

    @property
    def passed(self) -> bool:
        return self.status == PASS


__all__ = ["FAIL", "PASS", "SKIP", "Check", "Result"]
