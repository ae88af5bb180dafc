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


def cpu_seconds(exclude: frozenset[int] = frozenset()) -> float:
    """CPU seconds (user + system) used so far by this process and every live
    process below it (the sims, Gymnasium's or SB3's workers, also those a
    forkserver started), except the pids in ``exclude`` and what runs below
    them; descendants are read from /proc (Linux), else left out."""
    total = time.process_time()
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    try:
        entries = [e for e in os.listdir("/proc") if e.isdigit()]
    except OSError:
        return total
    parent: dict[int, int] = {}
    used: dict[int, float] = {}
    for entry in entries:
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        # After ")": state, ppid, ...; utime and stime are the 12th and 13th.
        parent[int(entry)] = int(fields[1])
        used[int(entry)] = (int(fields[11]) + int(fields[12])) / tick
    me = os.getpid()
    below = {me}
    grew = True
    while grew:
        new = {pid for pid, ppid in parent.items() if ppid in below and pid not in below and pid not in exclude}
        below |= new
        grew = bool(new)
    return total + sum(used[pid] for pid in below if pid != me)


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


__all__ = ["CpuHog", "PhysicsLimit", "cpu_seconds", "make_envpool"]
