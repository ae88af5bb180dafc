"""Shared fixtures. Sim processes started by a test are stopped by it; the
autouse check below fails any test that leaves one behind."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import remoteenv
from remoteenv.agent.launch.launcher import pid_alive

# SB3 makes an empty /tmp/SB3-<time> folder on every learn() that has no logger
# set; the tests' (and their subprocesses') go into one folder removed at exit.
_SB3_LOGDIR = tempfile.mkdtemp(prefix="sb3-test-logs-")
os.environ["SB3_LOGDIR"] = _SB3_LOGDIR
atexit.register(shutil.rmtree, _SB3_LOGDIR, True)


def wait_gone(pid: int, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not pid_alive(pid):
            return True
        time.sleep(0.02)
    return not pid_alive(pid)


def _processes() -> dict[int, tuple[int, bytes]]:
    """``{pid: (parent pid, command line)}`` of the live processes (no zombies)."""
    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                rest = f.read().rsplit(")", 1)[1].split()
            if rest[0] == "Z":
                continue
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                found[int(entry)] = (int(rest[1]), f.read())
        except (FileNotFoundError, ProcessLookupError, IndexError):
            continue
    return found


def _sim_children() -> set[int]:
    """Pids of running scene processes this test process started: its children
    that run a scene, and the children of its zygotes (which fork sims)."""
    me = os.getpid()
    processes = _processes()
    zygotes = {
        pid for pid, (parent, cmd) in processes.items() if parent == me and b"sim/process/zygote/start.py" in cmd
    }
    return {
        pid
        for pid, (parent, cmd) in processes.items()
        if (parent == me and b"--ready-file" in cmd) or parent in zygotes
    }


@pytest.fixture(autouse=True)
def no_leftover_sims():
    """Fail a test that leaves a sim process of its own running."""
    before = _sim_children()
    yield
    leftover = _sim_children() - before
    deadline = time.monotonic() + 5.0
    while leftover and time.monotonic() < deadline:
        time.sleep(0.05)
        leftover = {p for p in leftover if pid_alive(p)}
    assert not leftover, f"sim processes left running after the test: {sorted(leftover)}"


@pytest.fixture
def closing():
    """Register envs to close after the test, whatever happens."""
    envs = []
    yield envs.append
    for env in envs:
        env.close()


@pytest.fixture
def scene_path():
    return remoteenv.scene_path


@pytest.fixture(name="pid_alive")
def pid_alive_fixture():
    """The function ``pid_alive(pid) -> bool`` (tests cannot import conftest)."""
    return pid_alive


@pytest.fixture(name="wait_gone")
def wait_gone_fixture():
    """The function ``wait_gone(pid, timeout=5.0) -> bool``."""
    return wait_gone
