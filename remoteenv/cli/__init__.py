"""``python -m remoteenv <command>``: one module per command, each with
``add_parser(subparsers)`` and ``run(args) -> int``.

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import NoReturn

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.cli.optional import is_optional, missing_message

#: Command name -> module in remoteenv.cli, in the order ``--help`` lists them.
COMMANDS = {
    "demo": "demo",
    "new-scene": "new_scene",
    "bench": "bench",
    "keys": "keys_command",
    "launch": "launch",
    "check": "check",
    "latency-sweep": "latency_sweep",
    "latency-study": "latency_study",
}


class OneLineErrors(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2),
    naming the command and where its usage is, instead of the usage above it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (usage: {self.prog} --help)\n")


def main(argv: Sequence[str] | None = None) -> int:
    parser = OneLineErrors(
        prog="python -m remoteenv",
        description="remoteenv: MuJoCo simulations in their own processes, driven as Gymnasium envs.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in COMMANDS.values():
        module = importlib.import_module(f"remoteenv.cli.{module_name}")
        module.add_parser(sub)
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except ModuleNotFoundError as exc:
        if not is_optional(exc):
            raise
        print(missing_message(exc.name or "", f"python -m remoteenv {args.command}"), file=sys.stderr)
        return 2
    except RemoteEnvError as exc:
        # A sim refused what the command asked (its scene's arguments, the
        # memory it would take, ...): the reason, on one line; details are in
        # the exception's text for code that calls the API directly.
        print(f"python -m remoteenv {args.command}: error: {first_line(exc)}", file=sys.stderr)
        return 1


def first_line(exc: BaseException, limit: int = 1000) -> str:
    """The first line of ``exc``'s message (at most ``limit`` characters)."""
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:limit]


if __name__ == "__main__":
    sys.exit(main())
