"""Protocol compliance suite: checks any server speaking the remoteenv wire must pass.

The protocol is written down first (:mod:`remoteenv.wire.protocol`, with
:mod:`remoteenv.wire.codec.spaces` and :mod:`remoteenv.wire.messages.batch_encoding`); these checks
hold a server to it, whatever it runs on: the reference MuJoCo sim, a bridge
to a real robot, another language. Three ways to run them:

- ``python -m remoteenv check LAUNCH_INFO_FILE`` (exit 0 = compliant);
- :func:`run_suite` on a :class:`Target` (see :func:`targets_from_launch_info`);
- :class:`ComplianceTests`, a pytest base class with one test per check
  (imported lazily: the rest needs no pytest).

The checks speak the wire themselves over a ZeroMQ DEALER socket (CURVE when
the launch-info file gives keys); they use only the wire layer and the
launch-info reader of the agent side.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from remoteenv.compliance.check_results import FAIL, PASS, SKIP, Check, Result
from remoteenv.compliance.failures import CheckFailed, CheckSkipped
from remoteenv.compliance.probe import Probe, Target, targets_from_launch_info
from remoteenv.compliance.suite import CHECKS, compliant, format_report, run_check, run_suite

if TYPE_CHECKING:
    from remoteenv.compliance.pytest_base import ComplianceTests


def __getattr__(name: str) -> Any:
    if name == "ComplianceTests":
        from remoteenv.compliance.pytest_base import ComplianceTests

        return ComplianceTests
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CHECKS",
    "FAIL",
    "PASS",
    "SKIP",
    "Check",
    "CheckFailed",
    "CheckSkipped",
    "ComplianceTests",
    "Probe",
    "Result",
    "Target",
    "compliant",
    "format_report",
    "run_check",
    "run_suite",
    "targets_from_launch_info",
]
