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
