"""The latency examples run as documented (tiny budgets; what they print is
measured, not asserted)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_training_with_the_world_paused_during_updates_runs_both_ways():
    pytest.importorskip("stable_baselines3")
    done = subprocess.run(
        [sys.executable, os.path.join(ROOT, "examples", "latency_realtime_pause.py"), "--budget", "256"],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ, PYTHONPATH=ROOT),
    )
    assert done.returncode == 0, done.stderr[-3000:]
    lines = [line for line in done.stdout.splitlines() if "latency ticks" in line]
    assert len(lines) == 2
    assert lines[0].startswith("no pause") and "0 pauses" in lines[0]
    assert lines[1].startswith("pause() during updates") and " 0 pauses" not in lines[1]
