"""``python -m remoteenv <command>``: one module per command, each with
``add_parser(subparsers)`` and ``run(args) -> int``."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

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


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
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


if __name__ == "__main__":
    sys.exit(main())
