"""``bench --pixels`` runs end to end on a tiny case and writes well-formed JSON
(its figures are measurements, never asserted)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from remoteenv.agent.vector.vector_layout import default_envs_per_process
from remoteenv.benchmarks.pixels import parse_cases, ratios


def test_a_tiny_pixel_benchmark_writes_every_contender_and_the_ratios(tmp_path):
    out = tmp_path / "pixels.json"
    cmd = [sys.executable, "-m", "remoteenv", "bench", "--pixels", "--pixels-cases", "16x2"]
    cmd += ["--pixels-rounds", "1", "--pixels-duration", "0.1", "--pixels-k", "2", "--json", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(out.read_text())
    names = [r["name"] for r in result["rows"]]
    assert names == ["SyncVectorEnv", "AsyncVectorEnv", "RemoteVectorEnv", "RemoteVectorEnv K=2"]
    assert all(r["steps_per_s"] > 0 and (r["side"], r["num_envs"]) == (16, 2) for r in result["rows"])
    assert {r["ratio"] for r in result["ratios"]} == {
        "RemoteVectorEnv / AsyncVectorEnv",
        "RemoteVectorEnv / SyncVectorEnv",
    }
    assert set(result["render_cost_ms"]) == {"default", "cheap", "msaa only", "shadows only"}


def test_the_scene_that_renders_in_its_hook_gets_the_costly_layout_in_the_benchmark(tmp_path):
    out = tmp_path / "hook.json"
    cmd = [sys.executable, "-m", "remoteenv", "bench", "--pixels", "--pixels-render-in-hook", "--pixels-cases", "32x4"]
    cmd += ["--pixels-rounds", "1", "--pixels-duration", "0.1", "--json", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(out.read_text())
    assert result["render_in_hook"] is True
    remote = next(r for r in result["rows"] if r["name"] == "RemoteVectorEnv")
    assert remote["envs_per_process"] == default_envs_per_process(4, float("inf"))  # measured as costly
    assert [r["name"] for r in result["rows"]] == ["SyncVectorEnv", "AsyncVectorEnv", "RemoteVectorEnv"]


def test_cases_and_ratios():
    assert parse_cases("64x8, 84x16") == [(64, 8), (84, 16)]
    with pytest.raises(SystemExit, match="SIDExWORLDS"):
        parse_cases("64")
    rows = [
        {"side": 64, "num_envs": 8, "name": name, "steps_per_s": rate}
        for name, rate in (("SyncVectorEnv", 100.0), ("AsyncVectorEnv", 200.0), ("RemoteVectorEnv", 300.0))
    ]
    found = {r["ratio"]: (r["value"], r["target"]) for r in ratios(rows, (64, 8))}
    assert found == {"RemoteVectorEnv / AsyncVectorEnv": (1.5, 1.5), "RemoteVectorEnv / SyncVectorEnv": (3.0, 1.2)}
