"""The compliance suite: every check in order, a runner and a readable report.

Order matters only for two checks: ``step_before_reset`` runs before any
check resets a world (it needs a fresh one), and ``close`` runs last (it
stops the server). Every check opens its own connection and resets the
worlds it uses, so any subset runs on its own.

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence

from remoteenv.compliance import checks_attributes, checks_batch, checks_episode, checks_wire
from remoteenv.compliance.check_results import FAIL, PASS, SKIP, Check, Result
from remoteenv.compliance.failures import CheckFailed, CheckSkipped
from remoteenv.compliance.probe import Probe, Target
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import short_repr

#: Every check, in the order they run.
CHECKS: tuple[Check, ...] = (
    *checks_wire.CHECKS[:1],  # handshake
    *checks_episode.CHECKS[:1],  # step_before_reset: before anything resets a world
    *checks_wire.CHECKS[1:],
    *checks_episode.CHECKS[1:],
    *checks_batch.CHECKS,
    *checks_attributes.CHECKS,
    checks_episode.CLOSE,  # last: it stops the server
)

#: Longest reason shown on a report line (characters).
REASON_CHARS = 400


def run_check(check: Check, target: Target) -> Result:
    """Run one check on a fresh connection to ``target``; never raises."""
    started = time.perf_counter()
    try:
        with Probe(target) as probe:
            note = check.run(probe)
        status, reason = PASS, note or ""
    except CheckSkipped as exc:
        status, reason = SKIP, str(exc)
    except CheckFailed as exc:
        status, reason = FAIL, str(exc)
    except Exception as exc:  # a reply the checks did not foresee; report it, do not crash the suite
        status, reason = FAIL, f"the check raised {type(exc).__name__}: {short_repr(str(exc))}"
    return Result(check, status, reason, time.perf_counter() - started)


def unreachable(target: Target) -> str | None:
    """Why ``target`` does not answer a handshake at all, or None if it answers."""
    with Probe(target) as probe:
        probe.send("handshake", protocol=protocol.PROTOCOL_VERSION)
        if probe.frame_within(target.timeout):
            return None
    curve = " (with CURVE: are the keys right?)" if target.curve_server_key is not None else ""
    return f"no reply to a handshake from {target.endpoint} within {target.timeout:g} s{curve}; is the server running?"


def run_suite(target: Target, checks: Sequence[Check] = CHECKS) -> list[Result]:
    """Run ``checks`` in order on ``target``. If it does not answer at all, every
    check fails at once with that reason (instead of waiting out each one)."""
    why = unreachable(target)
    if why is not None:
        return [Result(check, FAIL, why) for check in checks]
    return [run_check(check, target) for check in checks]


def compliant(results: Iterable[Result]) -> bool:
    """True if no check failed (skips do not count against a server)."""
    return all(r.status != FAIL for r in results)


def format_result(result: Result, name_width: int = 20) -> str:
    """One report line: status, name, description and the reason (if any)."""
    reason = result.reason if len(result.reason) <= REASON_CHARS else result.reason[: REASON_CHARS - 3] + "..."
    line = f"{result.status.upper():<5} {result.check.name:<{name_width}} {result.check.description}"
    return f"{line}: {reason}" if reason else line


def summary(results: Sequence[Result]) -> str:
    counts = {s: sum(r.status == s for r in results) for s in (PASS, FAIL, SKIP)}
    verdict = "COMPLIANT" if compliant(results) else "NOT COMPLIANT"
    return f"{counts[PASS]} passed, {counts[FAIL]} failed, {counts[SKIP]} skipped: {verdict}"


def format_report(target: Target, results: Sequence[Result]) -> str:
    """A report of ``results`` on ``target``: a header, one line per check, a summary."""
    source = f" (from {target.source})" if target.source else ""
    width = max((len(r.check.name) for r in results), default=0)
    lines = [f"protocol compliance of instance {target.instance} at {target.endpoint}{source}"]
    lines += [format_result(r, width) for r in results]
    lines.append(summary(results))
    return "\n".join(lines)


__all__ = ["CHECKS", "compliant", "format_report", "format_result", "run_check", "run_suite", "summary", "unreachable"]
