"""Shared fixtures. Sim processes started by a test are stopped by it; the
autouse check below fails any test that leaves one behind."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import remoteenv
from remoteenv.agent.launch.launcher import pid_alive
from remoteenv.agent.launch.private_dir import MAX_SOCKET_PATH, socket_path_length

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


#: Integration test files whose assertions hold on wall-clock pacing, CPU
#: placement or the process table: ``make test`` runs them alone (``-m serial``)
#: after the other tests ran two at a time (pytest-xdist, ``-m "not serial"``),
#: so that no test of the others' load decides them. They pass beside two CPU
#: hogs too; this only keeps CI's verdict about the code, not the scheduler.
SERIAL_FILES = frozenset(
    {
        "test_action_delay.py",
        "test_bench_action_timing.py",
        "test_default_layout.py",
        "test_exact_twin.py",
        "test_hardening_cleanup.py",
        "test_hardening_orphans.py",
        "test_hardening_real_time.py",
        "test_latency_channel.py",
        "test_latency_real_time.py",
        "test_latency_twin.py",
        "test_many_agents.py",
        "test_real_time.py",
        "test_real_time_stalls.py",
        "test_sim_placement.py",
    }
)

#: Seconds a test's sims may take to exit after it ends (generous: with tests
#: running two at a time beside their sims, a close under load is slow).
SIMS_GONE_WITHIN_S = 20.0


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name in SERIAL_FILES:
            item.add_marker(pytest.mark.serial)


@pytest.fixture(autouse=True)
def no_leftover_sims():
    """Fail a test that leaves a sim process of its own running."""
    before = _sim_children()
    yield
    leftover = _sim_children() - before
    deadline = time.monotonic() + SIMS_GONE_WITHIN_S
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


@pytest.fixture
def agent_tmpdir():
    """A short empty directory for the ``TMPDIR`` of agents a test starts, removed after.

    Short so that their launches' private dirs, ipc sockets included, are made
    in it rather than moved to a shorter base (``private_dir.make_private_dir``):
    a test that looks for what they leave then looks where they are."""
    tmp = tempfile.mkdtemp(prefix="rs-", dir="/tmp")
    assert socket_path_length(tmp, 1000) <= MAX_SOCKET_PATH, tmp
    yield Path(tmp)
    shutil.rmtree(tmp, ignore_errors=True)


@pytest.fixture(name="pid_alive")
def pid_alive_fixture():
    """The function ``pid_alive(pid) -> bool`` (tests cannot import conftest)."""
    return pid_alive


@pytest.fixture(name="wait_gone")
def wait_gone_fixture():
    """The function ``wait_gone(pid, timeout=5.0) -> bool``."""
    return wait_gone


class Opened(NamedTuple):
    """One session a vector env's launch opened (see :func:`opened_sessions`)."""

    processes: int
    worlds_each: int
    measured: bool  # asked in its handshake what a world costs
    probe: bool  # a probe, closed once it answered
    gated: bool  # started through the layout gate


@pytest.fixture
def opened_sessions(monkeypatch):
    """Every session a vector env's launch opens, as :class:`Opened`, in order;
    the layouts learnt (layout_memory) are forgotten before and after."""
    from remoteenv.agent.vector import layout_memory, vector_launch

    layout_memory.forget_all()
    opened: list[Opened] = []
    real_open = vector_launch.open_session

    def counted(source, label, scene, slices, k, **options):
        gated = getattr(source, "layout_gate", None) is not None
        opened.append(Opened(slices, k, options["measure_world_cost"], options.get("probe", False), gated))
        return real_open(source, label, scene, slices, k, **options)

    monkeypatch.setattr(vector_launch, "open_session", counted)
    yield opened
    layout_memory.forget_all()
