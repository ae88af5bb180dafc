"""Stand-ins the unit tests share: a torch module that only counts threads, a
shipped scene's env class loaded from its script, a pipe connection that
offers a region of this process, and hot waits allowed as on two CPUs."""

from __future__ import annotations

import importlib.util
import os
import socket
import sys
import threading
import time
import types
from collections.abc import Callable
from typing import Any

import pytest

import remoteenv
from remoteenv.agent.vector import torch_threads
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory import hot_wait
from remoteenv.wire.shared_memory.doorbell import Doorbell
from remoteenv.wire.shared_memory.shared_batch import SharedLayout


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


class RegionConn:
    """A pipe connection whose sim offers ``fd`` of this process as its region;
    :meth:`post` only numbers the requests posted there (no sim reads them)."""

    waits_in_turn = True
    instance = 0
    endpoint = "pipe"

    def __init__(self, fd: int, layout: SharedLayout) -> None:
        self.pid = os.getpid()
        self.fd = fd
        self.layout = layout
        #: ``(n, named, plain)`` of each request posted.
        self.posted: list[tuple[int, bool, bool]] = []

    def request(self, cmd: str, **args: object) -> dict:
        return {"pid": self.pid, "fd": self.fd, "layout": self.layout.to_wire()}

    def post(self, doorbell: object, n: int, named: bool, think_s: float = 0.0, plain: bool = False) -> int:
        self.posted.append((n, named, plain))
        return len(self.posted)


def hot_waits_allowed(monkeypatch: pytest.MonkeyPatch) -> None:
    """Hot waits as on a two-CPU machine with no stall behind them (whatever this one is)."""
    monkeypatch.delenv("REMOTEENV_NO_SPIN", raising=False)
    monkeypatch.setattr(hot_wait, "usable_cpus", lambda: 2)
    monkeypatch.setattr(hot_wait._Neighbours, "cool_until", 0.0)
    monkeypatch.setattr(hot_wait._Neighbours, "last_stall", float("-inf"))
    monkeypatch.setattr(hot_wait._Neighbours, "cool_s", 0.0)


def in_thread(work: Callable[[], None]) -> threading.Thread:
    """Run a stand-in sim's ``work`` in a daemon thread (started)."""
    thread = threading.Thread(target=work, daemon=True)
    thread.start()
    return thread


def until(predicate: Callable[[], bool], timeout: float = 10.0) -> None:
    """Wait (polling every 0.2 ms) until ``predicate()``; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "the agent never blocked asking for a heads-up"
        time.sleep(0.0002)


def heads_up_once_asked(sim_bell: Doorbell, sock: socket.socket, seq: int) -> None:
    """The stand-in sim's physics is done: once the agent sleeps asking, send it a heads-up for ``seq``."""
    until(sim_bell.agent_wants_heads_up)
    sock.sendall(protocol.stream_frame(protocol.reply_soon(seq)))


class IdleRouter:
    """A channel on which nothing comes (the sim server's ZeroMQ router, here a quiet socket)."""

    def __init__(self, sock: socket.socket) -> None:
        self.closed, self.more = False, False
        self.pollable = self.fd = sock.fileno()

    def receive_nowait(self) -> list[tuple[Any, Any]]:
        return []
