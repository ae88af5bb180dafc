"""The anchors a batched remoteenv is measured against, and a CPU hog.

Agent side (benchmarks only). :class:`PhysicsLimit` is the ceiling: raw
``mujoco.mj_step`` over N ``MjData`` of a scene's model, one thread per
usable CPU, no env logic at all. :func:`make_envpool` is the fastest
in-process alternative a user could pick (EnvPool's C++ thread pool;
optional: ``pip install remoteenv[bench]``). :class:`CpuHog` keeps CPUs busy
beside a measurement, as training does beside stepping; :func:`cpu_seconds`
counts the CPU a contender's processes use, which on a shared host says
more about a design's cost than its steps per wall second.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from typing import Any

import mujoco
import numpy as np

from remoteenv.sim.stepping.batch_physics import PhysicsThreads
from remoteenv.wire.shared_memory.hot_wait import usable_cpus


class PhysicsLimit:
    """N worlds of the MJCF model at ``model_path``, stepped ``frame_skip``
    substeps per call on ``threads`` threads (default one per usable CPU), with random controls."""

    def __init__(
        self, model_path: str, num_worlds: int, frame_skip: int, seed: int = 0, threads: int | None = None
    ) -> None:
        self.num_envs = num_worlds
        self.model = mujoco.MjModel.from_xml_path(model_path)
        self.datas = [mujoco.MjData(self.model) for _ in range(num_worlds)]
        rng = np.random.default_rng(seed)
        for d in self.datas:
            d.ctrl[:] = rng.uniform(-1.0, 1.0, size=self.model.nu)
        self.models = [self.model] * num_worlds
        self.frame_skip = frame_skip
        self.physics = PhysicsThreads(threads or usable_cpus())

    def step(self) -> None:
        """One control tick of every world."""
        self.physics.step(self.models, self.datas, self.frame_skip)

    def close(self) -> None:
        self.physics.close()


def make_envpool(task_id: str, num_envs: int, batch_size: int | None = None) -> Any:
    """EnvPool's Gymnasium env for ``task_id`` on one thread per usable CPU
    (raises ImportError when EnvPool is not installed)."""
    import envpool

    kwargs: dict[str, Any] = {"num_envs": num_envs, "num_threads": usable_cpus(), "seed": 0}
    if batch_size is not None:
        kwargs["batch_size"] = batch_size
    return envpool.make_gymnasium(task_id, **kwargs)


def _proc_stat(pid: int | str) -> list[str] | None:
    """The fields of ``/proc/<pid>/stat`` after the command name, or None if it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def process_tree(exclude: frozenset[int] = frozenset()) -> set[int]:
    """This process and every live process below it (read from /proc: Linux;
    elsewhere this process alone), except the pids in ``exclude`` and what runs below them."""
    me = os.getpid()
    try:
        entries = [e for e in os.listdir("/proc") if e.isdigit()]
    except OSError:
        return {me}
    parent: dict[int, int] = {}
    for entry in entries:
        fields = _proc_stat(entry)
        if fields is not None:
            parent[int(entry)] = int(fields[1])  # after ")": state, ppid, ...
    below = {me}
    grew = True
    while grew:
        new = {pid for pid, ppid in parent.items() if ppid in below and pid not in below and pid not in exclude}
        below |= new
        grew = bool(new)
    return below


def cpu_seconds(exclude: frozenset[int] = frozenset()) -> float:
    """CPU seconds (user + system) used so far by this process and every live
    process below it (the sims, Gymnasium's or SB3's workers, also those a
    forkserver started), except the pids in ``exclude`` and what runs below
    them; descendants are read from /proc (Linux), else left out."""
    total = time.process_time()
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    me = os.getpid()
    for pid in process_tree(exclude) - {me}:
        fields = _proc_stat(pid)
        if fields is not None:  # utime and stime are the 12th and 13th after ")"
            total += (int(fields[11]) + int(fields[12])) / tick
    return total


def context_switches(pids: set[int]) -> tuple[int, int]:
    """``(voluntary, involuntary)`` context switches so far of every thread of ``pids``
    (Linux's ``/proc/<pid>/task/*/status``; (0, 0) elsewhere)."""
    voluntary = involuntary = 0
    for pid in pids:
        try:
            tasks = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for task in tasks:
            try:
                with open(f"/proc/{pid}/task/{task}/status") as f:
                    for line in f:
                        if line.startswith("voluntary_ctxt_switches:"):
                            voluntary += int(line.split()[1])
                        elif line.startswith("nonvoluntary_ctxt_switches:"):
                            involuntary += int(line.split()[1])
            except (OSError, ValueError, IndexError):
                continue
    return voluntary, involuntary


class CpuHog:
    """``count`` processes spinning on the CPU until :meth:`stop` (a context manager)."""

    def __init__(self, count: int) -> None:
        self.count = count
        self._procs: list[subprocess.Popen[bytes]] = []

    def __enter__(self) -> CpuHog:
        self._procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(self.count)]
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def pids(self) -> frozenset[int]:
        return frozenset(proc.pid for proc in self._procs)

    def stop(self) -> None:
        for proc in self._procs:
            proc.kill()
            proc.wait()
        self._procs = []


__all__ = ["CpuHog", "PhysicsLimit", "context_switches", "cpu_seconds", "make_envpool", "process_tree"]
