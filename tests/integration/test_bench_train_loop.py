"""``bench --train-loop`` runs end to end on a tiny case and writes well-formed
JSON (its figures are measurements, never asserted); its ratios and its
contender specs are computed as documented."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from remoteenv.benchmarks.train_loop import _contender, format_table, ratios


def test_a_tiny_training_loop_benchmark_writes_every_contender_and_the_ratios(tmp_path):
    out = tmp_path / "train.json"
    cmd = [sys.executable, "-m", "remoteenv", "bench", "--train-loop", "--train-n", "2"]
    cmd += ["--train-contenders", "remoteenv,SyncVectorEnv,SyncVectorEnv:OMP_NUM_THREADS=1"]
    cmd += ["--train-rounds", "2", "--train-duration", "0.05", "--json", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(out.read_text())
    rows = {r["name"]: r for r in result["rows"]}
    assert set(rows) == {"remoteenv", "SyncVectorEnv", "SyncVectorEnv:OMP_NUM_THREADS=1"}
    for row in rows.values():
        assert row["num_envs"] == 2 and len(row["rates"]) == 2 and row["median"] > 0
        assert row["cpu_us_per_step"] > 0 and set(row["wall_share"]) == {"act", "env_step", "update"}
        # Each slot's host speed: the run's fastest probe over the slower of its two, so (0, 1].
        assert len(row["host_speeds"]) == 2 and all(0 < x <= 1 for x in row["host_speeds"])
        # Each slot's steal share: the part of the CPUs' time the VM's host held (None without /proc/stat).
        assert len(row["host_steals"]) == 2 and all(x is None or 0 <= x <= 1 for x in row["host_steals"])
    assert rows["SyncVectorEnv:OMP_NUM_THREADS=1"]["torch_threads"] == 1
    assert rows["remoteenv"]["processes"] >= 2  # the trainer and its sim
    assert len(result["load_avg_per_round"]) == 2 and result["machine"]["cpus"] >= 1
    assert result["host_probe_fastest_s"] > 0

    # The run shown again and drawn from its JSON, nothing run.
    figure = tmp_path / "train.png"
    cmd = [sys.executable, "-m", "remoteenv", "bench", "--train-loop", "--train-from", str(out)]
    again = subprocess.run(cmd + ["--train-plot", str(figure)], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "SyncVectorEnv:OMP_NUM_THREADS=1" in again.stdout and "building" not in again.stdout
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (tmp_path / "other.json").write_text('{"rows": [{"name": "x"}]}')
    bad = subprocess.run(cmd[:-1] + [str(tmp_path / "other.json")], capture_output=True, text=True, timeout=120)
    assert bad.returncode != 0 and "is not a result of --train-loop --json" in bad.stderr


def test_contender_specs_and_ratios():
    assert _contender("EnvPool") == ("EnvPool", {})
    assert _contender("remoteenv:OMP_NUM_THREADS=1:X=y") == ("remoteenv", {"OMP_NUM_THREADS": "1", "X": "y"})
    with pytest.raises(SystemExit, match="KEY=VALUE"):
        _contender("remoteenv:OMP_NUM_THREADS")
    rows = [
        {"name": name, "num_envs": 16, "median": rate, "cpu_us_per_step": cpu}
        for name, rate, cpu in (("remoteenv", 300.0, 50.0), ("EnvPool", 200.0, 100.0), ("SyncVectorEnv", 100.0, 25.0))
    ]
    found = {r["ratio"]: (r["value"], r["target"]) for r in ratios(rows)}
    assert found == {
        "remoteenv / EnvPool, N=16": (1.5, 1.0),
        "remoteenv / SyncVectorEnv, N=16": (3.0, 1.5),
        "CPU/step: remoteenv / EnvPool, N=16": (2.0, None),
        "CPU/step: remoteenv / SyncVectorEnv, N=16": (0.5, None),
    }


def _package(root, marker: str) -> None:
    """A stand-in ``remoteenv.benchmarks.train_loop_worker`` under ``root`` that answers ``marker``."""
    worker = root / "remoteenv" / "benchmarks"
    worker.mkdir(parents=True)
    (root / "remoteenv" / "__init__.py").write_text("")
    (worker / "__init__.py").write_text("")
    (worker / "train_loop_worker.py").write_text(
        "import json, os, sys\n"
        "fd = int(sys.argv[sys.argv.index('--out-fd') + 1])\n"
        f"os.write(fd, (json.dumps({{'module': {marker!r}}}) + '\\n').encode())\n"
        "sys.stdin.read()\n"
    )


def test_a_contender_with_its_own_pythonpath_runs_that_code_whatever_the_working_directory(tmp_path, monkeypatch):
    from remoteenv.benchmarks.train_loop import Trainer

    _package(tmp_path / "cwd", "working directory")
    _package(tmp_path / "checkout", "its PYTHONPATH")
    monkeypatch.chdir(tmp_path / "cwd")  # e.g. the repository's root, another checkout of the project
    trainer = Trainer("remoteenv", 4, {"PYTHONPATH": str(tmp_path / "checkout")})
    try:
        assert trainer.ready == {"module": "its PYTHONPATH"}
    finally:
        trainer.close()


def test_each_ratio_carries_its_ratio_round_by_round_and_the_table_counts_the_rounds_that_met_it():
    rows = [
        {"name": "remoteenv", "num_envs": 16, "median": 110.0, "rates": [90.0, 110.0, 120.0], "cpu_us_per_step": 1.0},
        {"name": "EnvPool", "num_envs": 16, "median": 100.0, "rates": [100.0, 100.0, 100.0], "cpu_us_per_step": 1.0},
        # A row whose rounds cannot be paired (another count): no ratio round by round.
        {"name": "SyncVectorEnv", "num_envs": 16, "median": 50.0, "rates": [50.0], "cpu_us_per_step": 1.0},
    ]
    found = {r["ratio"]: r for r in ratios(rows)}
    assert found["remoteenv / EnvPool, N=16"]["rounds"] == pytest.approx([0.9, 1.1, 1.2])
    assert found["remoteenv / SyncVectorEnv, N=16"]["rounds"] == []
    result = {
        "rows": rows,
        "ratios": list(found.values()),
        "machine": {"cpus": 2, "platform": "p", "python": "3"},
        "load_avg_per_round": [1.0],
        "date": "d",
        "rounds": 3,
        "duration_s": 1.0,
        "hogs": 0,
        "train_env": {},
        "skipped": [],
    }
    rows[0]["wall_share"] = rows[1]["wall_share"] = rows[2]["wall_share"] = {"act": 0, "env_step": 0, "update": 0}
    for r in rows:
        r.update(trainer_cpu_us_per_step=1.0, voluntary_switches_per_step=0.0, involuntary_switches_per_step=0.0)
    lines = format_table(result).splitlines()
    [envpool] = [line for line in lines if line.startswith("remoteenv / EnvPool, N=16")]
    assert envpool.split()[-6:] == ["1.10", "0.90-1.20", ">=1.0", "met", "(2/3", "rounds)"]
    [sync] = [line for line in lines if line.startswith("remoteenv / SyncVectorEnv, N=16")]
    assert sync.split()[-3:] == ["2.20", ">=1.5", "met"]
    # A result written before ratios had their rounds still reads: the verdict alone.
    for r in result["ratios"]:
        r.pop("rounds", None)
    [envpool] = [line for line in format_table(result).splitlines() if line.startswith("remoteenv / EnvPool, N=16")]
    assert envpool.split()[-3:] == ["1.10", ">=1.0", "met"]
    # A round with no rate to divide by: no ratio round by round at all, rather than a shorter list.
    rows[1]["rates"] = [100.0, 0.0, 100.0]
    assert {r["ratio"]: r for r in ratios(rows)}["remoteenv / EnvPool, N=16"]["rounds"] == []
