"""The delay-effect study command runs end to end on a tiny budget and writes
well-formed outputs. The learning result itself is never asserted here (a
few thousand steps learn nothing): docs/latency.md reports the full run."""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from remoteenv.latency.study.design import cells

pytest.importorskip("stable_baselines3")
pytest.importorskip("matplotlib")


def test_a_reduced_study_writes_every_record_the_table_the_figure_and_the_twin_check(tmp_path):
    out = tmp_path / "study"
    cmd = [
        sys.executable,
        "-m",
        "remoteenv",
        "latency-study",
        "--delays",
        "0,2",
        "--random-delays",
        "1:2",
        "--seeds",
        "0,1",
        "--steps",
        "512",
        "--eval-episodes",
        "2",
        "--workers",
        "2",
        "--rt-episodes",
        "2",
        "--out",
        str(out),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    data = json.loads((out / "delay_effect.json").read_text())
    records = data["records"]
    keys = {(r["variant"], r["kind"], r["delay"], r["seed"]) for r in records}
    expected = {
        (v, kind, d, s)
        for kind, delays in (("constant", (0, 2)), ("random", ("U(1,2)",)))
        for d in delays
        for v in ("plain", "history")
        for s in (0, 1)
        if (v, d) != ("history", 0)  # no action in flight: history at 0 is plain
    }
    assert keys == expected and len(records) == len(expected)
    for r in records:
        assert r["variant"] in ("plain", "history")
        assert len(r["returns"]) == 2 and math.isclose(r["mean_return"], float(np.mean(r["returns"])))
        assert all(ret >= 1 for ret in r["returns"])  # CartPole pays +1 per step survived
        # random delays keep one action more than the largest delay: the in-force one at its largest age
        random = r["kind"] == "random"
        assert r["history_length"] == ((3 if random else r["delay"]) if r["variant"] == "history" else 0)
        assert r["include_alpha"] == (r["variant"] == "history" and random)
        assert r["steps"] == 512 and r["train_s"] > 0
        if r["delay"] != 0:  # what the delays did during the evaluation episodes
            assert 0 <= r["dropped_fraction"] <= 1
            low, high = (1, 2) if random else (r["delay"], r["delay"])
            assert low - 1 <= r["mean_age_ticks"] <= high
    assert data["config"]["delays"] == [0, 2] and data["wall_s"] > 0 and data["host"]["cpus"] >= 1
    refs = data["references"]
    assert set(refs["random"]) == {"LQR (delay-unaware)", "expected-state predictor (buffer + alpha)"}
    assert all(set(by_delay) == {"U(1,2)"} for by_delay in refs["random"].values())
    table = (out / "delay_effect.md").read_text()
    assert "| U(1,2) |" in table and "| 2 |" in table
    assert (out / "delay_effect.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    twin = json.loads((out / "rt_replay.json").read_text())
    assert [(p["variant"], p["trained_delay"]) for p in twin["policies"]] == [
        ("plain", 0),
        ("plain", 0),
        ("history", 2),
        ("history", 2),
    ]
    assert [p["seed"] for p in twin["policies"]] == [0, 1, 0, 1]  # the training seeds
    assert len({p["episode_seed"] for p in twin["policies"]}) == 4
    for p in twin["policies"]:
        assert len(p["real_time"]["returns"]) == len(p["lock_step_returns"]) == 2
        assert p["replay"] == p["real_time"]  # the exact twin repeats every episode
    assert twin["identical"] == twin["total"] == 8


def test_a_resumed_study_keeps_what_it_finished_and_refuses_another_configuration(tmp_path):
    out = tmp_path / "study"
    base = [sys.executable, "-m", "remoteenv", "latency-study", "--out", str(out), "--no-rt-replay", "--no-plot"]
    base += ["--random-delays", "", "--seeds", "0", "--steps", "256", "--eval-episodes", "1", "--workers", "1"]
    first = subprocess.run([*base, "--delays", "0"], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr[-3000:]
    before = json.loads((out / "delay_effect.json").read_text())["records"]
    again = subprocess.run([*base, "--delays", "0", "--resume"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-3000:]
    after = json.loads((out / "delay_effect.json").read_text())["records"]
    assert after == before  # nothing left to train: the records are kept as they were
    other = subprocess.run([*base, "--delays", "1", "--resume"], capture_output=True, text=True, timeout=300)
    assert other.returncode != 0 and "another configuration" in other.stderr


def test_an_unwritable_out_fails_before_any_training(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    done = subprocess.run(
        [sys.executable, "-m", "remoteenv", "latency-study", "--out", str(blocker / "sub")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode != 0 and "not writable" in done.stderr
    assert "delay study" not in done.stderr  # no progress bar: nothing started


def test_the_trained_policy_normalises_observations_as_vec_normalize_did(tmp_path):
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from remoteenv.latency.study.training import TrainedPolicy

    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")]), norm_reward=False)
    venv.reset()
    for _ in range(50):
        venv.step(np.array([[0.5]]))
    stats = {
        "mean": venv.obs_rms.mean,
        "var": venv.obs_rms.var,
        "clip": np.array(venv.clip_obs),
        "epsilon": np.array(venv.epsilon),
    }
    obs = np.array([0.3, -0.9, 7.5], dtype=np.float32)
    policy = TrainedPolicy(model=None, obs_stats=stats)
    np.testing.assert_allclose(policy.normalize(obs), venv.normalize_obs(obs), rtol=1e-6)
    venv.close()


@pytest.mark.parametrize("bad", ["fifo", "1e308"])
def test_a_resume_file_that_fails_its_checks_is_refused_in_one_line_and_nothing_is_published(tmp_path, bad):
    """Issue 28, item 2: a FIFO no longer hangs ``--resume``, and records claiming
    every cell done with returns CartPole cannot give never become the table."""
    out = tmp_path / "study"
    out.mkdir()
    path = out / "delay_effect.json"
    args = ["--random-delays", "", "--delays", "0", "--seeds", "0", "--steps", "256", "--eval-episodes", "1"]
    if bad == "fifo":
        os.mkfifo(path)
    else:
        from remoteenv.cli.latency_study import _config, add_parser  # the study's own configuration

        parser = argparse.ArgumentParser()
        add_parser(parser.add_subparsers())
        config = _config(parser.parse_args(["latency-study", *args]))
        records = [
            {"variant": c.variant, "kind": c.kind, "delay": c.delay, "seed": c.seed, "mean_return": 1e308}
            | {"returns": [1e308], "history_length": c.history_length, "include_alpha": c.include_alpha}
            | {"steps": 256, "train_s": 1.0, "train_return": 1e308, "curve": []}
            for c in cells(config)
        ]
        path.write_text(json.dumps({"config": config.to_json(), "records": records}))
    done = subprocess.run(
        [sys.executable, "-m", "remoteenv", "latency-study", "--out", str(out), "--resume", "--no-plot", *args],
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode != 0 and len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert str(path) in lines[0]
    assert not (out / "delay_effect.md").exists()


def _descendants(root: int) -> set[int]:
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/stat") as f:
                parents[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    found, frontier = set(), {root}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def test_a_sigtermed_study_leaves_no_dir_and_no_process(tmp_path, agent_tmpdir, pid_alive):
    """Issue 28, item 6: SIGTERM while the workers train leaves no
    ``remoteenv-study-policies-*`` dir (nor any private dir) and no process."""
    # A short TMPDIR: multiprocessing's manager binds a Unix socket in it,
    # and pytest's tmp_path (its run counter in it) can pass the 107-byte limit.
    tmp = agent_tmpdir
    log = tmp_path / "stderr"
    cmd = [sys.executable, "-m", "remoteenv", "latency-study", "--out", str(tmp_path / "study"), "--no-plot"]
    cmd += ["--random-delays", "", "--delays", "0", "--seeds", "0", "--steps", "100000", "--workers", "2"]
    with open(log, "w") as err:
        study = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, env={**os.environ, "TMPDIR": str(tmp)})
    left: set[int] = set()
    try:
        deadline = time.monotonic() + 120
        while "delay study" not in log.read_text() and study.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert list(tmp.glob("remoteenv-study-policies-*")), f"no scratch dir: {log.read_text()[-2000:]}"
        time.sleep(2.0)  # the workers are training
        left = _descendants(study.pid)
        study.terminate()
        assert study.wait(timeout=60) != 0
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and (list(tmp.glob("remoteenv-*")) or any(pid_alive(p) for p in left)):
            time.sleep(0.1)
        assert not list(tmp.glob("remoteenv-*")), sorted(os.listdir(tmp))
        assert not [p for p in left if pid_alive(p)]
    finally:
        if study.poll() is None:
            study.kill()
            study.wait()
        for pid in left:
            if pid_alive(pid):
                os.kill(pid, 9)


@pytest.mark.parametrize("obs_mode", ["pixels", "state_pixels"])
def test_a_study_on_the_camera_cartpole_trains_a_cnn_with_the_history_beside_the_image(tmp_path, obs_mode):
    out = tmp_path / "study"
    kwargs = json.dumps({"continuous": True, "obs_mode": obs_mode, "image_size": 36})
    cmd = [sys.executable, "-m", "remoteenv", "latency-study", "--env-kwargs", kwargs, "--out", str(out)]
    cmd += ["--delays", "2", "--random-delays", "", "--seeds", "0", "--steps", "128", "--eval-episodes", "1"]
    cmd += ["--workers", "1", "--rt-episodes", "2", "--no-plot"]
    cmd += ["--ppo", json.dumps({"n_steps": 16, "batch_size": 64, "n_epochs": 1})]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "| 128/256 [" in done.stderr and "step/s" in done.stderr  # the bar counts training steps (2 runs x 128)
    records = json.loads((out / "delay_effect.json").read_text())["records"]
    assert sorted(r["variant"] for r in records) == ["history", "plain"]
    assert all(len(r["returns"]) == 1 and r["returns"][0] >= 1 for r in records)
    assert json.loads((out / "delay_effect.json").read_text())["references"] is None  # no LQR on pixels
    twin = json.loads((out / "rt_replay.json").read_text())  # real time with pixels, replayed in lock-step
    assert twin["policies"] and all(len(p["real_time"]["returns"]) == 2 for p in twin["policies"])


def test_a_space_the_study_cannot_train_on_is_refused_before_the_study_starts(tmp_path):
    out = tmp_path / "study"
    kwargs = json.dumps({"continuous": True, "obs_mode": "pixels", "image_size": 24})
    cmd = [sys.executable, "-m", "remoteenv", "latency-study", "--env-kwargs", kwargs, "--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "latency-study cannot train on remoteenv/CartPole-v0" in done.stderr
    assert "smaller than the 36x36 SB3's CNN takes" in done.stderr and '"image_size": 64' in done.stderr
    assert not out.exists()  # nothing trained, nothing written
