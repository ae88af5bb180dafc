"""Where a vector env's own lock-step sims run: one CPU each, as batch work.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`). In lock step
the agent wakes its sims with a write to each one's pipe, then waits. Linux
places a task woken that way next to its waker and lets it preempt the
waker, so by default the first sim runs on the agent's CPU, the agent's
writes to the other sims wait behind it, and the sims step one after the
other instead of side by side. With ``place_sims="auto"`` (the default) the
vector env, for the sims it started itself on this machine and never in
real time:

* gives each sim ``SCHED_BATCH`` (a normal-priority policy for throughput
  work: a woken sim no longer preempts the agent, which finishes waking
  every sim before it waits): its main thread, which serves the requests;
  physics threads it started before keep the normal policy, which trains
  faster at N = 16 (docs/performance-history.md, "The physics' second thread"), and
* when there are at least two sims and no more than the CPUs this process
  may use, and each sim steps its worlds on one thread (no
  ``REMOTEENV_SIM_THREADS`` above 1), pins sim ``i`` to the ``i``-th of
  those CPUs, so that the sims step side by side.

Nothing of the user's process changes. A sim relaunched after a crash is
placed again at the next ``reset``. A pinned sim that a busy neighbour
keeps waiting for its CPU takes the other CPUs back by itself, and tries
its CPU again later (:mod:`remoteenv.sim.process.pin_release`);
:attr:`SimPlacement.cpus` says where it was pinned, not where it runs
while it is released. Where the OS refuses (no
``sched_setaffinity``, another user's process) the sims run as they are.
``place_sims=None`` leaves the sims to the OS scheduler. Measured gain:
docs/performance.md ("The learner beside the sims").
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from remoteenv.wire.shared_memory.hot_wait import usable_cpus

#: ``place_sims`` value that places the sims.
AUTO = "auto"
#: Environment variable of the sims' physics threads (:mod:`remoteenv.sim.stepping.batch_physics`).
SIM_THREADS_ENV = "REMOTEENV_SIM_THREADS"


def check_place_sims(value: object) -> str | None:
    """``value`` if it is a valid ``place_sims`` (``"auto"`` or None), else a ValueError."""
    if value is None or value == AUTO:
        return value
    raise ValueError(f"place_sims must be 'auto' or None, got {value!r:.80}")


def _one_physics_thread() -> bool:
    value = os.environ.get(SIM_THREADS_ENV, "")
    return not value.strip() or value.strip() == "1"


def placement(pids: Sequence[int], cpus: Sequence[int], one_thread: bool) -> list[int | None]:
    """The CPU each sim of ``pids`` is pinned to (None: not pinned), given the
    CPUs ``cpus`` the agent may use and whether each sim steps on one thread."""
    if one_thread and 2 <= len(pids) <= len(cpus):
        ordered = sorted(cpus)
        return [ordered[i] for i in range(len(pids))]
    return [None] * len(pids)


def _cpus() -> list[int]:
    try:
        return sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return list(range(usable_cpus()))


def place(pid: int, cpu: int | None) -> bool:
    """Make ``pid`` batch work (and pin it to ``cpu`` if given); False if the OS refused."""
    try:
        if hasattr(os, "SCHED_BATCH"):
            os.sched_setscheduler(pid, os.SCHED_BATCH, os.sched_param(0))
        if cpu is not None and hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(pid, {cpu})
    except OSError:
        return False
    return True


class SimPlacement:
    """The ``place_sims`` choice of one vector env; :meth:`apply` places its
    sims (at construction and each ``reset``; only sims not placed yet)."""

    def __init__(self, choice: str | None, *, own_sims: bool, real_time: bool) -> None:
        self.active = check_place_sims(choice) == AUTO and own_sims and not real_time
        self._placed: list[int] = []
        #: The CPU each sim was pinned to at the last placement (None: not pinned).
        self.cpus: list[int | None] = []

    def apply(self, pids: Sequence[int | None]) -> None:
        """Place the sims ``pids`` (this env's, on this machine) unless they are placed already."""
        if not self.active or any(p is None for p in pids):
            return
        local = [int(p) for p in pids if p is not None]
        if local == self._placed:
            return
        self._placed = local
        self.cpus = placement(local, _cpus(), _one_physics_thread())
        for pid, cpu in zip(local, self.cpus):
            place(pid, cpu)


__all__ = ["AUTO", "SIM_THREADS_ENV", "SimPlacement", "check_place_sims", "place", "placement"]
