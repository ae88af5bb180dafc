"""Stand-ins the unit tests share: a torch module that only counts threads, and
a shipped scene's env class loaded from its script."""

from __future__ import annotations

import importlib.util
import sys
import types
from typing import Any

import pytest

import remoteenv
from remoteenv.agent.vector import torch_threads


class FakeTorch(types.ModuleType):
    """``torch`` as far as thread counts go: ``set_num_threads`` calls are kept in ``calls``."""

    def __init__(self, threads: int) -> None:
        super().__init__("torch")
        self.threads = threads
        self.calls: list[int] = []

    def get_num_threads(self) -> int:
        return self.threads

    def set_num_threads(self, n: int) -> None:
        self.calls.append(n)
        self.threads = n


def fake_torch_on(monkeypatch: pytest.MonkeyPatch, cpus: int) -> FakeTorch:
    """A :class:`FakeTorch` loaded as ``torch`` at ``cpus`` threads, on a machine of
    ``cpus`` usable CPUs, with neither ``OMP_NUM_THREADS`` nor an earlier "auto" in force."""
    torch = FakeTorch(cpus)
    monkeypatch.setitem(sys.modules, "torch", torch)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setattr(torch_threads._Applied, "done", False)
    monkeypatch.setattr(torch_threads, "usable_cpus", lambda: cpus)
    return torch


def scene_class(name: str, cls: str, module_name: str) -> Any:
    """Class ``cls`` of the shipped scene ``name``'s script, loaded as module ``module_name``."""
    spec = importlib.util.spec_from_file_location(module_name, remoteenv.scene_path(name))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return getattr(module, cls)
