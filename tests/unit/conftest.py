"""Unit tests run inside this process only: starting any process here fails the test."""

from __future__ import annotations

import os
import subprocess

import pytest


def _refuse(*args: object, **kwargs: object) -> None:
    raise AssertionError("a unit test tried to start a process; move it to tests/integration/")


@pytest.fixture(autouse=True)
def no_processes(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make every way of starting a process raise for the duration of a unit test."""
    monkeypatch.setattr(subprocess.Popen, "__init__", _refuse)
    for name in ("fork", "forkpty", "posix_spawn", "posix_spawnp", "system", "execv", "execve"):
        if hasattr(os, name):
            monkeypatch.setattr(os, name, _refuse)


@pytest.fixture
def lane(monkeypatch):
    """An agent's pipe and doorbell, the stand-in sim's socket and doorbell on the same header
    (no cool-down left by an earlier stall in this process)."""
    import socket

    import numpy as np
    from fakes import hot_waits_allowed

    from remoteenv.agent.connection.pipe_connection import PipeConnection
    from remoteenv.wire.shared_memory.doorbell import Doorbell

    hot_waits_allowed(monkeypatch)
    agent_end, sim_end = socket.socketpair()
    header = np.zeros(16, dtype="<i8")
    conn = PipeConnection(agent_end, timeout=10.0)
    yield conn, Doorbell(header, silent=True), sim_end, Doorbell(header, silent=True)
    conn.close()
    sim_end.close()
