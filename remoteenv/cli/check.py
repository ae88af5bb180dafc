"""``python -m remoteenv check LAUNCH_INFO_FILE``: the protocol compliance suite.

Runs every check of :mod:`remoteenv.compliance` on the servers a launch-info
file names and prints one line per check and a summary per server. Exit
status: 0 when every server is compliant (no check failed), 1 when one is
not, 2 when the launch-info file cannot be used.

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from remoteenv.cli.arguments import non_negative_int, positive_seconds


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "check",
        help="check that the servers of a launch-info file follow the wire protocol",
        description="Run the protocol compliance suite against the servers a launch-info file names "
        "(written by `python -m remoteenv launch` or by any server speaking the protocol). "
        "Exit 0 = compliant, 1 = not, 2 = the file cannot be used.",
    )
    p.add_argument("launch_info", metavar="LAUNCH_INFO_FILE", help="the launch-info file")
    p.add_argument(
        "--instance",
        type=non_negative_int,
        default=None,
        help="check only this instance of the file (default: every one)",
    )
    p.add_argument(
        "--allow-close", action="store_true", help="also check 'close', which stops the server (default: skipped)"
    )
    p.add_argument("--timeout", type=positive_seconds, default=10.0, help="seconds to wait for each reply (default 10)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from remoteenv.agent.errors import RemoteEnvError
    from remoteenv.compliance import compliant, format_report, run_suite, targets_from_launch_info

    try:
        targets = targets_from_launch_info(
            args.launch_info, args.instance, timeout=args.timeout, allow_close=args.allow_close
        )
    except RemoteEnvError as exc:
        print(f"cannot check: {exc}", file=sys.stderr)
        return 2
    failed = 0
    for i, target in enumerate(targets):
        results = run_suite(target)
        if i:
            print()
        print(format_report(target, results), flush=True)
        failed += not compliant(results)
    if len(targets) > 1:
        print(f"\n{len(targets) - failed} of {len(targets)} servers compliant")
    return 1 if failed else 0
