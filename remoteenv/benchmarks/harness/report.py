"""How the table benchmarks hand out a result: a table on stdout, and its JSON
to a file (``--json PATH``) or, with ``--json -``, JSON alone on stdout (the
progress lines then go to stderr).

Runs in the agent process (benchmarks only).
"""

from __future__ import annotations

import json
import os
import platform
import sys
from collections.abc import Callable
from typing import Any


def machine_record() -> dict[str, Any]:
    """The machine a benchmark ran on, for its JSON: CPU count, platform, Python version."""
    return {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()}


def progress_log(json_path: str | None) -> Callable[[str], None]:
    """Where progress lines go: stderr when stdout carries the JSON, else stdout."""
    if json_path == "-":
        return lambda line: print(line, file=sys.stderr)
    return print


def emit(result: dict[str, Any], json_path: str | None, format_table: Callable[[dict[str, Any]], str]) -> None:
    """Print ``result`` as its table (and write its JSON to ``json_path``), or as JSON on stdout for ``-``."""
    if json_path == "-":
        json.dump(result, sys.stdout, indent=2)
        print()
        return
    print()
    print(format_table(result))
    if json_path:
        with open(json_path, "w") as f:
            json.dump(result, f, indent=2)
        print(f"\nwrote {json_path}")
