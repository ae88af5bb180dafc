"""The training examples train on any registered id (--env), save, load and
evaluate. Tiny budgets: that they run and save/load, never what they learn."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from remoteenv.cli.new_scene import write_package

pytest.importorskip("torch")
pytest.importorskip("tqdm")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EXAMPLES = os.path.join(ROOT, "examples")


def _run(script: str, args: list[str], cwd, pythonpath: list[str]) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([*pythonpath, ROOT]), MUJOCO_GL="egl")
    return subprocess.run(
        [sys.executable, os.path.join(EXAMPLES, script), *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture
def scene_package(tmp_path):
    """A package new-scene wrote (continuous actions, no reward threshold), importable but never installed."""
    write_package("ball_plate", tmp_path / "ball_plate")
    return str(tmp_path / "ball_plate" / "src")


def test_torch_ppo_on_cartpole_by_default(tmp_path):
    out = _run(
        "train_ppo.py",
        ["--budget", "256", "--num-envs", "2", "--rollout-steps", "64", "--eval-episodes", "1"],
        tmp_path,
        [],
    )
    # CartPole's reward threshold is the target, which 256 steps do not reach: exit status 1.
    assert out.returncode == 1, out.stderr[-3000:]
    assert "did NOT reach the target 475" in out.stdout
    assert (tmp_path / "cartpole_ppo.pt").is_file()
    assert "evaluation (1 lock-step episodes, greedy)" in out.stdout


def test_torch_ppo_on_a_package_of_your_own(tmp_path, scene_package):
    args = ["--env", "ball_plate:ball_plate/BallPlate-v0", "--budget", "256", "--num-envs", "2"]
    args += ["--rollout-steps", "64", "--eval-episodes", "1", "--save", "policy.pt", "--think-ms", "0"]
    out = _run("train_ppo.py", args, tmp_path, [scene_package])
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.startswith("trained:") or "\ntrained:" in out.stdout
    assert "real-time evaluation" in out.stdout
    again = _run(
        "train_ppo.py", ["--eval-only", "--save", "policy.pt", "--eval-episodes", "1"], tmp_path, [scene_package]
    )
    assert again.returncode == 0, again.stderr[-3000:]
    first = [line for line in out.stdout.splitlines() if line.startswith("evaluation")]
    assert [line for line in again.stdout.splitlines() if line.startswith("evaluation")] == first  # the same policy


def test_sb3_ppo_on_a_package_of_your_own(tmp_path, scene_package):
    pytest.importorskip("stable_baselines3")
    args = ["--env", "ball_plate:ball_plate/BallPlate-v0", "--steps", "128", "--n-steps", "64", "--num-envs", "2"]
    args += ["--eval-episodes", "1", "--save", "model.zip"]
    out = _run("train_sb3.py", args, tmp_path, [scene_package])
    assert out.returncode == 0, out.stderr[-3000:]
    assert "trained SB3 PPO on ball_plate/BallPlate-v0 for 128 steps" in out.stdout
    assert (tmp_path / "model.zip").is_file()
    again = _run("train_sb3.py", [*args, "--eval-only"], tmp_path, [scene_package])
    assert again.returncode == 0, again.stderr[-3000:]
    assert again.stdout.splitlines()[-1] == out.stdout.splitlines()[-1]  # the saved model, evaluated alike


@pytest.mark.parametrize(("obs_mode", "network"), [("pixels", "CnnPolicy"), ("state_pixels", "MultiInputPolicy")])
def test_sb3_ppo_on_the_camera_cartpole(tmp_path, obs_mode, network):
    pytest.importorskip("stable_baselines3")
    kwargs = f'{{"obs_mode": "{obs_mode}", "image_size": 36}}'  # SB3's CNN takes 36x36 and larger
    args = ["--steps", "64", "--n-steps", "32", "--num-envs", "2", "--eval-episodes", "1", "--save", "model.zip"]
    out = _run("train_sb3.py", [*args, "--env-kwargs", kwargs], tmp_path, [])
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.startswith(f"{network} for observations")
    assert "trained SB3 PPO on remoteenv/CartPole-v0 for 64 steps" in out.stdout
    assert "evaluation (1 episodes, deterministic)" in out.stdout


@pytest.mark.parametrize("obs_mode", ["pixels", "state_pixels"])
def test_torch_ppo_on_the_camera_cartpole(tmp_path, obs_mode):
    kwargs = f'{{"obs_mode": "{obs_mode}", "image_size": 36}}'
    args = ["--budget", "128", "--num-envs", "2", "--rollout-steps", "64", "--eval-episodes", "1"]
    args += ["--reward-scale", "0.01", "--ent-coef", "0.01", "--torch-threads", "2"]  # the pixel recipe's settings
    out = _run("train_ppo.py", [*args, "--env-kwargs", kwargs, "--save", "cam.pt"], tmp_path, [])
    assert out.returncode == 1, out.stderr[-3000:]  # 128 steps do not reach CartPole's target
    assert "did NOT reach the target 475" in out.stdout
    first = [line for line in out.stdout.splitlines() if line.startswith("evaluation")]
    assert first, out.stdout
    # The saved policy carries its env kwargs and its CNN: evaluated again alike.
    again = _run("train_ppo.py", ["--eval-only", "--save", "cam.pt", "--eval-episodes", "1"], tmp_path, [])
    assert again.returncode == 0, again.stderr[-3000:]
    assert [line for line in again.stdout.splitlines() if line.startswith("evaluation")] == first


def test_torch_ppo_refuses_a_reward_scale_that_is_not_positive(tmp_path):
    out = _run("train_ppo.py", ["--reward-scale", "0", "--budget", "64"], tmp_path, [])
    assert out.returncode == 2
    assert "--reward-scale must be > 0, got 0.0" in out.stderr
