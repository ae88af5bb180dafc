"""Stepping the physics of many worlds at once on threads (the GIL released).

Runs in the sim process. ``mujoco.mj_step`` releases the GIL while it
computes, so the worlds of one process can advance on every CPU it is given:
:class:`PhysicsThreads` splits a batch of worlds into contiguous chunks, runs
the first on the calling thread and the others on worker threads, and
returns when all are done. Each world keeps its own ``MjData``, so the
scene's hooks (per world or batched) read and write it as before, and a
world's trajectory does not depend on the number of threads.

Chosen over ``mujoco.rollout`` (which also steps many states on threads)
because rollout works on state vectors and scratch ``MjData``: derived
quantities such as ``xpos`` that scenes read after a step would have to be
recomputed, and every world's ``MjData`` copied in and out each step. On the
2-core reference machine the two measured alike for Reacher at N = 64
(see docs/performance.md).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import mujoco

#: Environment variable that fixes the number of physics threads of every
#: sim process (an int >= 1); unset, :func:`default_threads` decides.
THREADS_ENV = "REMOTEENV_SIM_THREADS"
#: Fewest worlds per thread worth a thread of its own: below it the hand-off
#: (~10-30 us) costs more than the physics it moves.
MIN_WORLDS_PER_THREAD = 8


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def default_threads(num_worlds: int) -> int:
    """Physics threads for a process hosting ``num_worlds`` worlds: one per
    usable CPU, but no more than one per :data:`MIN_WORLDS_PER_THREAD` worlds;
    the environment variable :data:`THREADS_ENV` overrides."""
    fixed = os.environ.get(THREADS_ENV)
    if fixed:
        try:
            value = int(fixed)
        except ValueError:
            raise ValueError(f"{THREADS_ENV} must be an int >= 1, got {fixed[:20]!r}") from None
        if value < 1:
            raise ValueError(f"{THREADS_ENV} must be an int >= 1, got {value}")
        return value
    return max(1, min(usable_cpus(), num_worlds // MIN_WORLDS_PER_THREAD))


class PhysicsThreads:
    """Advances many ``(model, data)`` worlds by ``nstep`` substeps each, on ``threads`` threads.

    Args:
        threads: threads to use, the caller's included (1: step on the caller's thread only).
    """

    def __init__(self, threads: int) -> None:
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        self.threads = int(threads)
        self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="physics") if self.threads > 1 else None

    def step(self, models: Sequence[mujoco.MjModel], datas: Sequence[mujoco.MjData], nstep: int) -> None:
        """``mj_step(models[i], datas[i], nstep)`` for every ``i``; returns when all are done.

        An exception from any world is raised here (after the others finished)."""
        n = len(datas)
        chunks = min(self.threads, n)
        if chunks <= 1 or self._pool is None:
            _step_range(models, datas, nstep, 0, n)
            return
        bounds = [n * c // chunks for c in range(chunks + 1)]
        futures = [
            self._pool.submit(_step_range, models, datas, nstep, bounds[c], bounds[c + 1]) for c in range(1, chunks)
        ]
        try:
            _step_range(models, datas, nstep, bounds[0], bounds[1])
        finally:
            for future in futures:
                future.result()

    def close(self) -> None:
        """Stop the worker threads."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def _step_range(models: Sequence[mujoco.MjModel], datas: Sequence[mujoco.MjData], nstep: int, lo: int, hi: int) -> None:
    step = mujoco.mj_step
    for i in range(lo, hi):
        step(models[i], datas[i], nstep=nstep)


__all__ = ["MIN_WORLDS_PER_THREAD", "THREADS_ENV", "PhysicsThreads", "default_threads", "usable_cpus"]
