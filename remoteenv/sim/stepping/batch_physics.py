"""Stepping the physics of many worlds at once on threads (the GIL released).

Runs in the sim process. ``mujoco.mj_step`` releases the GIL while it
computes, so the worlds of one process can advance on every CPU it is given:
:class:`PhysicsThreads` cuts a batch of worlds into small chunks that
the calling thread and worker threads take in turn, and returns when all
are done. Each world keeps its own ``MjData``, so the
scene's hooks (per world or batched) read and write it as before, and a
world's trajectory does not depend on the number of threads.

Chosen over ``mujoco.rollout`` (which also steps many states on threads)
because rollout works on state vectors and scratch ``MjData``: derived
quantities such as ``xpos`` that scenes read after a step would have to be
recomputed, and every world's ``MjData`` copied in and out each step. On the
2-core reference machine the two measured alike for Reacher at N = 64
(see docs/performance-history.md).
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import mujoco

#: Environment variable that sets the number of physics threads of every sim
#: process (an int >= 1; see :func:`default_threads`). Sims inherit it from the agent.
THREADS_ENV = "REMOTEENV_SIM_THREADS"
#: Fewest worlds per thread worth a thread of its own: below it the hand-off
#: (~10-30 us) costs more than the physics it moves.
MIN_WORLDS_PER_THREAD = 8


def default_threads(num_worlds: int) -> int:
    """Physics threads for a process hosting ``num_worlds`` worlds: the
    environment variable :data:`THREADS_ENV` if set, else 1.

    One by default because that measured fastest: the default layout
    already runs at least one sim process per CPU once N is large. On the
    2-core reference machine, quiet, N = 64 stepped at 58.9k steps/s with
    K = 32 and one thread against 52.7k with K = 64 and two; on the same
    machine loaded (load average 7) a second thread per process cost a third
    (docs/performance-history.md). Set it to the CPUs a process may use when one
    sim process hosts many worlds on an otherwise idle machine (e.g. a
    remote host serving one agent); it is capped at one thread per
    :data:`MIN_WORLDS_PER_THREAD` worlds.
    """
    fixed = os.environ.get(THREADS_ENV)
    if not fixed:
        return 1
    try:
        value = int(fixed)
    except ValueError:
        raise ValueError(f"{THREADS_ENV} must be an int >= 1, got {fixed[:20]!r}") from None
    if value < 1:
        raise ValueError(f"{THREADS_ENV} must be an int >= 1, got {value}")
    return max(1, min(value, num_worlds // MIN_WORLDS_PER_THREAD))


class PhysicsThreads:
    """Advances many ``(model, data)`` worlds by ``nstep`` substeps each, on ``threads`` threads.

    The worlds are cut into small chunks that the calling thread and the
    workers take in turn until none is left, so a worker the OS is slow to
    wake (a loaded host) costs nothing: the caller steps its share too, and
    waits only for chunks a worker has started.

    Args:
        threads: threads to use, the caller's included (1: step on the caller's thread only).
    """

    #: Chunks per thread: small enough to share the work out evenly.
    CHUNKS_PER_THREAD = 4

    def __init__(self, threads: int) -> None:
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        self.threads = int(threads)
        self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="physics") if self.threads > 1 else None

    def step(self, models: Sequence[mujoco.MjModel], datas: Sequence[mujoco.MjData], nstep: int) -> None:
        """``mj_step(models[i], datas[i], nstep)`` for every ``i``; returns when all are done.

        An exception from any world is raised here (after the chunks under way finished)."""
        n = len(datas)
        if self._pool is None or n < 2:
            _step_range(models, datas, nstep, 0, n)
            return
        job = _Job(models, datas, nstep, max(1, n // (self.threads * self.CHUNKS_PER_THREAD)))
        for _ in range(self.threads - 1):
            self._pool.submit(job.work)
        job.work()
        job.finished.wait()
        if job.error is not None:
            raise job.error

    def close(self) -> None:
        """Stop the worker threads."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


class _Job:
    """One :meth:`PhysicsThreads.step` call: chunks handed out by ticket, counted as done."""

    def __init__(
        self, models: Sequence[mujoco.MjModel], datas: Sequence[mujoco.MjData], nstep: int, chunk: int
    ) -> None:
        self.models, self.datas, self.nstep, self.chunk = models, datas, nstep, chunk
        self.num_chunks = -(-len(datas) // chunk)
        self._tickets = itertools.count()  # next() is atomic under the GIL
        self._lock = threading.Lock()
        self._done = 0
        self.error: BaseException | None = None
        self.finished = threading.Event()

    def work(self) -> None:
        n = len(self.datas)
        while True:
            c = next(self._tickets)
            if c >= self.num_chunks:
                return
            lo = c * self.chunk
            try:
                _step_range(self.models, self.datas, self.nstep, lo, min(lo + self.chunk, n))
            except BaseException as exc:
                self.error = exc
            with self._lock:
                self._done += 1
                if self._done == self.num_chunks:
                    self.finished.set()


def _step_range(models: Sequence[mujoco.MjModel], datas: Sequence[mujoco.MjData], nstep: int, lo: int, hi: int) -> None:
    step = mujoco.mj_step
    for i in range(lo, hi):
        step(models[i], datas[i], nstep=nstep)


__all__ = ["MIN_WORLDS_PER_THREAD", "THREADS_ENV", "PhysicsThreads", "default_threads"]
