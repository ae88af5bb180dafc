"""``bench --batched`` runs end to end on a tiny case and writes well-formed
JSON (its figures are measurements, never asserted)."""

from __future__ import annotations

import json
import subprocess
import sys


def test_a_tiny_batched_benchmark_writes_every_row_and_the_ratios(tmp_path):
    out = tmp_path / "batched.json"
    cmd = [sys.executable, "-m", "remoteenv", "bench", "--batched", "--batched-n", "4", "--batched-duration", "0.1"]
    cmd += ["--rounds", "1", "--no-heavy", "--json", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(out.read_text())
    assert list(result) == ["date", "machine", "load_avg_per_round", "hogs", "duration_s", "rounds", "rows", "ratios"]
    assert result["hogs"] == 0 and result["rounds"] == 1 and result["duration_s"] == 0.1
    assert len(result["load_avg_per_round"]) == 1 and result["machine"]["cpus"] >= 1
    rows = {(r["name"], r["num_envs"]): r for r in result["rows"]}
    expected = {"physics limit", "physics, 1 thread", "remoteenv batched", "remoteenv send/recv", "SyncVectorEnv"}
    assert {(name, 4) for name in expected} <= set(rows)
    assert {("remoteenv single", 1), ("AsyncVectorEnv", 1)} <= set(rows)
    assert not any(name.startswith("hexapod") for name, _ in rows)  # --no-heavy
    for row in rows.values():
        assert len(row["rates"]) == 1 and row["median"] > 0 and row["cpu_us_per_step"] > 0
    assert result["ratios"] and all({"ratio", "value", "target"} <= set(r) for r in result["ratios"])
