"""``python -m remoteenv bench --startup`` runs end to end and reports every row for both ways of starting sims."""

from __future__ import annotations

import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_startup_benchmark_reports_both_ways_and_every_row(tmp_path):
    out = tmp_path / "startup.json"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "remoteenv",
            "bench",
            "--startup",
            "--startup-repeats",
            "1",
            "--startup-later",
            "1",
            "--startup-vector",
            "2",
            "--startup-default-vector",
            "10",
            "--startup-json",
            str(out),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert "first make" in done.stdout and "vector, 2" in done.stdout and "later default vector, 10" in done.stdout
    result = json.loads(out.read_text())
    (quiet,) = result["passes"].values()
    for mode in ("zygote", "plain"):
        rows = quiet["summary"][mode]
        assert set(rows) == {"first make", "later make", "restart", "vector", "default vector", "later default vector"}
        assert all(row["n"] == 1 and row["median_s"] > 0 for row in rows.values())
