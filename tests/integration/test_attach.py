"""Attach: ``python -m remoteenv launch`` starts sims; other processes drive them."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest

from remoteenv import OpenAIRemoteEnv, RemoteEnvError, controllers
from remoteenv.agent.launch.attach import AttachedSim, LaunchInfo, read_launch_info, write_launch_info


def _start_launch(tmp_path, *extra):
    out = tmp_path / "launch.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "remoteenv", "launch", "cartpole", "--out", str(out), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    while not out.exists():
        if proc.poll() is not None:
            raise AssertionError(f"launch exited early ({proc.returncode}): {proc.stderr.read()}")
        time.sleep(0.05)
    return proc, out


def _stop_launch(proc, out):
    """SIGTERM the launch command; return the sim pids it had started."""
    pids = [s["pid"] for s in json.loads(out.read_text())["instances"]] if out.exists() else []
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    return pids


@pytest.fixture
def launched(tmp_path, wait_gone):
    proc, out = _start_launch(tmp_path, "--instances", "2", "--seed", "7")
    try:
        yield proc, out
    finally:
        pids = _stop_launch(proc, out)
        assert all(wait_gone(p) for p in pids), "sims outlived the launch command"


def test_launch_info_round_trip(tmp_path):
    info = LaunchInfo(
        scene="/x/scene.py",
        env_id="e/v0",
        launcher_pid=5,
        worlds_per_instance=2,
        real_time=True,
        instances=[AttachedSim(0, "ipc:///a", 11), AttachedSim(1, "tcp://h:5", None)],
    )
    write_launch_info(tmp_path / "l.json", info)
    back = read_launch_info(tmp_path / "l.json")
    assert back.to_json() == info.to_json()
    assert back.instances[1].pid is None and back.instances[1].death() is None


def test_bad_launch_info_files_are_named(tmp_path):
    with pytest.raises(RemoteEnvError, match="python -m remoteenv launch"):
        OpenAIRemoteEnv.attach(tmp_path / "missing.json")
    (tmp_path / "other.json").write_text('{"format": "something-else"}')
    with pytest.raises(RemoteEnvError, match="not a launch-info file"):
        read_launch_info(tmp_path / "other.json")
    (tmp_path / "broken.json").write_text('{"format": "remoteenv-launch/1", "instances": [{}]}')
    with pytest.raises(RemoteEnvError, match="malformed"):
        read_launch_info(tmp_path / "broken.json")


def test_attach_drives_launched_sims_and_leaves_them_running(launched, pid_alive):
    proc, out = launched
    info = read_launch_info(out)
    assert info.env_id == "remoteenv/CartPole-v0" and len(info.instances) == 2
    assert info.launcher_pid == proc.pid
    assert all(pid_alive(s.pid) for s in info.instances)

    trajectories = []
    for instance in (0, 1, 0):
        env = OpenAIRemoteEnv.attach(out, instance=instance)
        try:
            assert env.pid == info.instances[instance].pid
            obs, _ = env.reset(seed=3)
            rewards = []
            for _ in range(20):
                obs, reward, terminated, truncated, _ = env.step(controllers.cartpole_discrete(obs))
                rewards.append(reward)
            trajectories.append(obs)
        finally:
            env.close()
        assert pid_alive(info.instances[instance].pid), "closing an attached env stopped its sim"
    # Same seed and actions on different sims (and a re-attach) give the same trajectory.
    np.testing.assert_array_equal(trajectories[0], trajectories[1])
    np.testing.assert_array_equal(trajectories[0], trajectories[2])


def test_gym_make_attach_gets_time_limit_and_checkers(launched):
    _, out = launched
    env = gym.make("remoteenv/CartPole-v0", attach=str(out))
    try:
        obs, _ = env.reset(seed=0)
        steps, done = 0, False
        while not done:
            obs, _, terminated, truncated, _ = env.step(controllers.cartpole_discrete(obs))
            steps += 1
            done = terminated or truncated
        assert truncated and steps == 500
    finally:
        env.close()


def test_sims_stop_with_the_launch_command(tmp_path, wait_gone):
    proc, out = _start_launch(tmp_path, "--instances", "1")
    info = read_launch_info(out)
    env = OpenAIRemoteEnv.attach(out)
    try:
        env.reset(seed=0)
        pids = _stop_launch(proc, out)
        assert proc.returncode == 0
        assert all(wait_gone(p) for p in pids)
        assert not out.exists(), "the launch-info file outlived the launch command"
        with pytest.raises(RemoteEnvError) as err:
            env.step(0)
        assert err.value.kind == "died" and "launch command" in str(err.value)
    finally:
        env.close()
    assert "sims stopped" in proc.stdout.read()
    assert not os.path.exists(os.path.dirname(info.instances[0].endpoint[len("ipc://") :]))


def test_attach_with_curve_keys(tmp_path, wait_gone):
    proc, out = _start_launch(tmp_path, "--transport", "tcp", "--curve")
    try:
        info = read_launch_info(out)
        assert info.instances[0].curve_server_key is not None
        key_file = tmp_path / info.curve_client_secret_key_file
        assert key_file.exists() and (key_file.stat().st_mode & 0o077) == 0
        env = OpenAIRemoteEnv.attach(out)
        try:
            obs, _ = env.reset(seed=1)
            assert env.observation_space.contains(obs)
        finally:
            env.close()
    finally:
        pids = _stop_launch(proc, out)
        assert all(wait_gone(p) for p in pids)
    assert not key_file.exists()


def test_vector_env_attaches_to_every_world(tmp_path, wait_gone):
    from remoteenv.vector_env import RemoteVectorEnv

    proc, out = _start_launch(tmp_path, "--instances", "2", "--worlds", "2")
    try:
        with pytest.raises(ValueError, match="num_envs=4"):
            RemoteVectorEnv(read_launch_info(out).scene, 3, attach=str(out))
        venv = RemoteVectorEnv.attach(out, max_episode_steps=10)
        try:
            assert venv.num_envs == 4
            obs, _ = venv.reset(seed=11)
            assert obs.shape == (4, 4)
            truncated = np.zeros(4, dtype=bool)
            for _ in range(10):
                actions = np.array([controllers.cartpole_discrete(o) for o in obs])
                obs, rewards, terminated, truncated, _ = venv.step(actions)
            assert truncated.all() and not terminated.any()
        finally:
            venv.close()
        # The sims outlive the vector env; a single env can attach next and
        # sees the world that world 0 of the vector env saw.
        env = OpenAIRemoteEnv.attach(out, instance=0)
        try:
            single, _ = env.reset(seed=11)
        finally:
            env.close()
        venv = RemoteVectorEnv.attach(out)
        try:
            again, _ = venv.reset(seed=11)
        finally:
            venv.close()
        np.testing.assert_array_equal(again[0], single)
    finally:
        pids = _stop_launch(proc, out)
        assert pids and all(wait_gone(p) for p in pids)
