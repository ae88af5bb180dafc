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
import time
from collections.abc import Callable
from typing import Any


def machine_record() -> dict[str, Any]:
    """The machine a benchmark ran on, for its JSON: CPU count, platform, Python version."""
    return {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()}


def rounds_record(
    *,
    loads: list[float],
    hogs: int,
    duration_s: float,
    rounds: int,
    rows: list[dict[str, Any]],
    ratios: list[dict[str, Any]],
    **extra: Any,
) -> dict[str, Any]:
    """The JSON of a benchmark timed in alternating rounds: when and where it
    ran, the load average after each round, the CPU hogs beside it, the seconds
    per contender per round, then ``extra`` (the benchmark's own settings), its
    rows and the ratios of their medians."""
    return {
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
        "machine": machine_record(),
        "load_avg_per_round": loads,
        "hogs": hogs,
        "duration_s": duration_s,
        "rounds": rounds,
        **extra,
        "rows": rows,
        "ratios": ratios,
    }


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
