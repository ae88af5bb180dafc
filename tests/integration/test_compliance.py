"""The protocol compliance suite: the reference sims and an independent server pass it.

``servers/gym_cartpole_server.py`` is a second server written from the spec
alone (no remoteenv import): Gymnasium's CartPole-v1 behind pyzmq + msgpack,
standing in for a real robot bridge. It passes the suite, is driven by
``OpenAIRemoteEnv.attach`` like any sim, and, broken on purpose with
``--flaw``, shows the suite catching what it breaks.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from remoteenv import OpenAIRemoteEnv
from remoteenv.compliance import CHECKS, ComplianceTests

SERVER = Path(__file__).parent / "servers" / "gym_cartpole_server.py"
_ENV = {**os.environ, "MUJOCO_GL": "egl"}


@contextlib.contextmanager
def _running(cmd: list[str], out: Path) -> Iterator[subprocess.Popen]:
    """Run ``cmd`` until the test is done; yield once it has written the launch-info file ``out``."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_ENV)
    try:
        deadline = time.monotonic() + 120
        while not out.exists():
            if proc.poll() is not None:
                raise AssertionError(f"{cmd[1:3]} exited early ({proc.returncode}): {proc.stderr.read()}")
            assert time.monotonic() < deadline, f"{cmd[1:3]} wrote no launch-info file in 120 s"
            time.sleep(0.05)
        yield proc
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()  # type: ignore[union-attr]
        proc.stderr.close()  # type: ignore[union-attr]


def _launch(tmp_path: Path, *args: str, scene: str = "cartpole") -> contextlib.AbstractContextManager:
    out = tmp_path / "launch.json"
    return _running([sys.executable, "-m", "remoteenv", "launch", scene, "--out", str(out), *args], out)


def _independent(tmp_path: Path, *args: str) -> contextlib.AbstractContextManager:
    out = tmp_path / "bridge.json"
    return _running([sys.executable, str(SERVER), "--out", str(out), *args], out)


def _check(path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "remoteenv", "check", str(path), *args],
        capture_output=True,
        text=True,
        env=_ENV,
        timeout=300,
    )


def _statuses(report: str) -> dict[str, str]:
    """Check name -> PASS/FAIL/SKIP from a report's check lines."""
    names = {c.name for c in CHECKS}
    found = {}
    for line in report.splitlines():
        parts = line.split()
        if len(parts) > 1 and parts[0] in ("PASS", "FAIL", "SKIP") and parts[1] in names:
            found[parts[1]] = parts[0]
    return found


# ---------------------------------------------------------------- the base class on three servers


class TestReferenceLockStep(ComplianceTests):
    """Two worlds (batch commands), over tcp with CURVE; ``close`` last."""

    allow_close = True

    @pytest.fixture(scope="class")
    @classmethod
    def compliance_launch_info(cls, tmp_path_factory):
        tmp = tmp_path_factory.mktemp("lock_step")
        with _launch(tmp, "--worlds", "2", "--transport", "tcp", "--curve"):
            yield tmp / "launch.json"


class TestReferenceReacher(ComplianceTests):
    """Reacher's info (reward_dist, reward_ctrl: numpy scalars) travels as typed info columns."""

    @pytest.fixture(scope="class")
    @classmethod
    def compliance_launch_info(cls, tmp_path_factory):
        tmp = tmp_path_factory.mktemp("reacher")
        with _launch(tmp, "--worlds", "2", scene="reacher"):
            yield tmp / "launch.json"


class TestReferenceRealTime(ComplianceTests):
    """Two worlds on a paced clock (``timing``, no batch commands)."""

    @pytest.fixture(scope="class")
    @classmethod
    def compliance_launch_info(cls, tmp_path_factory):
        tmp = tmp_path_factory.mktemp("real_time")
        with _launch(tmp, "--real-time", "--worlds", "2"):
            yield tmp / "launch.json"


class TestIndependentServer(ComplianceTests):
    """Gymnasium's CartPole-v1 behind a server that imports nothing from remoteenv."""

    allow_close = True

    @pytest.fixture(scope="class")
    @classmethod
    def compliance_launch_info(cls, tmp_path_factory):
        tmp = tmp_path_factory.mktemp("independent")
        with _independent(tmp, "--worlds", "2", "--transport", "ipc"):
            yield tmp / "bridge.json"


# ---------------------------------------------------------------- the independent server as an env


def test_attach_drives_the_independent_server_like_gymnasium(tmp_path):
    with _independent(tmp_path) as proc:
        env = OpenAIRemoteEnv.attach(tmp_path / "bridge.json")
        reference = gym.make("CartPole-v1")
        try:
            assert env.pid == proc.pid
            assert env.observation_space == reference.observation_space
            assert env.action_space == reference.action_space
            obs, _ = env.reset(seed=11)
            expected, _ = reference.reset(seed=11)
            assert obs.dtype == np.float32
            np.testing.assert_array_equal(obs, expected)
            for t, action in enumerate([0, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 0]):
                obs, reward, terminated, truncated, _ = env.step(action)
                want = reference.step(action)
                np.testing.assert_array_equal(obs, want[0], err_msg=f"step {t}")
                assert (reward, terminated, truncated) == (want[1], want[2], want[3])
        finally:
            env.close()
            reference.close()
        assert proc.poll() is None, "closing an attached env stopped the server"


# ---------------------------------------------------------------- python -m remoteenv check


def test_check_command_passes_the_reference_and_skips_what_a_used_server_cannot_show(tmp_path):
    with _launch(tmp_path, "--worlds", "2"):
        first = _check(tmp_path / "launch.json")
        second = _check(tmp_path / "launch.json", "--instance", "0")
    assert first.returncode == 0, first.stdout + first.stderr
    statuses = _statuses(first.stdout)
    assert set(statuses) == {c.name for c in CHECKS}, first.stdout
    assert statuses["step_before_reset"] == "PASS" and statuses["close"] == "SKIP"
    assert "0 failed" in first.stdout and first.stdout.rstrip().endswith("COMPLIANT")
    # The first run reset every world: no fresh world is left, which is a skip, not a failure.
    assert second.returncode == 0, second.stdout
    assert _statuses(second.stdout)["step_before_reset"] == "SKIP"


@pytest.mark.parametrize(
    "flaw, failing",
    [
        ("seq", {"step", "invalid_action", "stale_replies"}),
        ("obs-dtype", {"reset", "step", "invalid_action", "bad_arguments", "render"}),
        ("silent-garbage", {"garbage_frames", "non_map_requests", "missing_seq_or_cmd", "malformed_arrays"}),
    ],
)
def test_check_command_names_each_broken_rule(tmp_path, flaw, failing):
    with _independent(tmp_path, "--flaw", flaw):
        result = _check(tmp_path / "bridge.json", "--timeout", "2")
    assert result.returncode == 1, result.stdout + result.stderr
    statuses = _statuses(result.stdout)
    assert {name for name, s in statuses.items() if s == "FAIL"} == failing, result.stdout
    assert statuses["handshake"] == "PASS"
    assert result.stdout.rstrip().endswith("NOT COMPLIANT")


def test_check_command_refuses_an_unusable_file(tmp_path):
    result = _check(tmp_path / "missing.json")
    assert result.returncode == 2 and "python -m remoteenv launch" in result.stderr


def test_check_command_reports_a_server_that_does_not_answer(tmp_path):
    with _independent(tmp_path) as proc:
        text = (tmp_path / "bridge.json").read_text()
    assert proc.poll() is not None
    (tmp_path / "gone.json").write_text(text)
    result = _check(tmp_path / "gone.json", "--timeout", "0.5")
    assert result.returncode == 1
    statuses = _statuses(result.stdout)
    assert set(statuses.values()) == {"FAIL"} and len(statuses) == len(CHECKS)
    assert "no reply to a handshake" in result.stdout
