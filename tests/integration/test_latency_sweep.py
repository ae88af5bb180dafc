"""``python -m remoteenv latency-sweep`` writes its table, JSON and plot (a tiny run)."""

from __future__ import annotations

import csv
import json

import pytest

from remoteenv.cli import main


@pytest.mark.parametrize("mode", ["action_delay", "obs_delay"])
def test_a_tiny_sweep_writes_csv_json_and_plot(tmp_path, mode):
    out = tmp_path / "sweep"
    argv = ["latency-sweep", "cartpole", "--policy", "cartpole_continuous", "--env-kwargs", '{"continuous": true}']
    argv += ["--mode", mode, "--delays", "0,3", "--seeds", "0,1", "--episodes", "2", "--max-steps", "30"]
    assert main([*argv, "--out", str(out)]) == 0
    with open(out / "sweep.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 * 2 * 2
    assert {(r["delay"], r["seed"], r["episode"]) for r in rows} == {
        (d, s, e) for d in "03" for s in "01" for e in "01"
    }
    doc = json.loads((out / "sweep.json").read_text())
    assert [s["delay"] for s in doc["summary"]] == [0, 3] and doc["config"]["mode"] == mode
    assert all(len(s["seed_means"]) == 2 for s in doc["summary"])
    if mode == "action_delay":  # constant delay 3: the action in force is 3 ticks old once the default is gone
        for r in rows:
            length = int(r["length"])
            if r["delay"] == "0":
                assert r["action_age_ticks"] == "" and r["actions_never_acted"] == ""
            else:
                assert float(r["action_age_ticks"]) == pytest.approx((3 * length - 3) / length)
                assert int(r["actions_never_acted"]) == 3  # the last three were on their way at the end
        assert doc["summary"][0]["mean_action_age_ticks"] is None
        assert 2 < doc["summary"][1]["mean_action_age_ticks"] < 3
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Lock-step repeats: the same sweep gives the same table.
    again = tmp_path / "again"
    assert main([*argv, "--out", str(again), "--no-plot"]) == 0
    with open(again / "sweep.csv") as f:
        assert list(csv.DictReader(f)) == rows


def test_a_real_time_sweep_reports_the_measured_latency(tmp_path):
    out = tmp_path / "rt"
    argv = ["latency-sweep", "remoteenv/CartPole-v0", "--policy", "cartpole_continuous", "--mode", "real_time"]
    argv += ["--env-kwargs", '{"continuous": true}', "--delays", "0,2", "--seeds", "0", "--episodes", "1"]
    assert main([*argv, "--max-steps", "10", "--no-plot", "--out", str(out)]) == 0
    summary = json.loads((out / "sweep.json").read_text())["summary"]
    # Thinking 2 ticks of wall time: the paced world runs about 2 ticks meanwhile,
    # so the latency is at least ~2 ticks (a lower bound only: load adds to it).
    assert summary[1]["mean_latency_ticks"] >= 1.5


def test_bad_arguments_are_named(tmp_path):
    with pytest.raises(SystemExit, match="--delays"):
        main(
            ["latency-sweep", "cartpole", "--policy", "cartpole_continuous", "--delays", "a,b", "--out", str(tmp_path)]
        )
    with pytest.raises(SystemExit, match="neither a builtin"):
        main(["latency-sweep", "cartpole", "--policy", "no_such_policy", "--out", str(tmp_path)])
