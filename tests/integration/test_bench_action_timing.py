"""``python -m remoteenv bench --action-timing`` runs end to end, reports both regimes, and
finds no step that acted before it was sent (an exact count: the bench counts only steps
certainly early, whatever the scheduler does)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_action_timing_benchmark_reports_both_regimes_and_no_early_step(tmp_path):
    out = tmp_path / "action_timing.json"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "remoteenv",
            "bench",
            "--action-timing",
            "--at-steps",
            "40",
            "--at-stall-trials",
            "1",
            "--json",
            str(out),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(out.read_text())
    assert [s["mode"] for s in result["steady"]] == ["elastic", "fixed_step"]
    for steady in result["steady"]:
        assert steady["steps"] == 40
        assert steady["acted_before_sent"] == 0 and steady["latency_below_think"] == 0, steady
    assert set(result["stalled"]) == {"elastic", "fixed_step"}
    for mode, (trial,) in result["stalled"].items():
        # The sim stopped 60 ms (3 ticks) from the reply: the action acts after the stall, the step is late.
        assert trial["late"] and trial["ticks_elapsed"] >= 3 and trial["latency_ticks"] >= 3, (mode, trial)
