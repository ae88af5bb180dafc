"""A pinned sim that a busy neighbour keeps off its CPU takes its other CPUs back.

Runs in the sim process, in lock step. The agent's vector env pins each of
its one-thread sims to a CPU of its own (``place_sims="auto"``, see
:mod:`remoteenv.agent.vector.sim_placement`): side by side on a quiet
machine they step faster so. But a CPU that another program keeps busy (a
CPU hog, another job, a learner running beside the sims) is shared in time
slices of milliseconds, and a pinned sim cannot move to a CPU that is free:
beside one CPU hog, pinned sims stepped 2.4–4.7× slower than sims left to
the OS (docs/performance.md). So every :data:`WINDOW` answers a pinned sim
reads from the kernel how long its serving thread waited, runnable, for a
CPU (``run_delay`` in ``/proc/<pid>/task/<tid>/schedstat``, which counts
the waits after each wake-up too) against how long it ran: when it waited at
least :data:`OFF_CPU_S` seconds in that window, and longer than it ran, it
takes back the CPUs it served on before it was pinned (once, logged; the
agent does not pin it again). Where the kernel does not say, nothing changes.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

#: Answers per look: how often a sim checks whether it is pinned and how long it waited for its CPU.
WINDOW = 32
#: Seconds a pinned sim must have waited for its CPU within a window to take its CPUs back.
OFF_CPU_S = 0.010


def _affinity() -> set[int] | None:
    try:
        return set(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return None


class SchedStat:
    """The kernel's run-time figures of the calling thread (Linux ``schedstat``)."""

    def __init__(self) -> None:
        self._fd: int | None = None
        try:
            self._fd = os.open(f"/proc/self/task/{threading.get_native_id()}/schedstat", os.O_RDONLY)
        except (OSError, AttributeError):
            pass

    def read(self) -> tuple[float, float] | None:
        """``(seconds run on a CPU, seconds waited runnable for one)`` so far, or None if unknown."""
        if self._fd is None:
            return None
        try:
            fields = os.pread(self._fd, 128, 0).split()
            return int(fields[0]) / 1e9, int(fields[1]) / 1e9
        except (OSError, ValueError, IndexError):
            return None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class PinRelease:
    """Watches the answers of sim instance ``instance`` on the calling (serving) thread.

    Call :meth:`answered` after each batch of answers (or wrap the server's
    answer with :meth:`watching`): a counter's increment, and every
    :data:`WINDOW` answers one ``sched_getaffinity`` (and, while pinned, one
    read of the thread's ``schedstat``).
    """

    def __init__(self, instance: int, stat: SchedStat | None = None) -> None:
        self.instance = instance
        #: The CPUs the sim may run on before anyone pins it (None: the OS cannot tell).
        self.start_cpus = _affinity()
        #: True once the sim took its CPUs back.
        self.released = False
        self._stat = stat if stat is not None else SchedStat()
        self._count = 0
        self._last: tuple[float, float] | None = None

    def answered(self) -> None:
        """One more batch of answers; every :data:`WINDOW`, judge the window."""
        self._count += 1
        if self._count < WINDOW:
            return
        self._count = 0
        if not self._is_pinned():
            self._last = None
            return
        now = self._stat.read()
        last, self._last = self._last, now
        if now is None or last is None:
            return
        ran, waited = now[0] - last[0], now[1] - last[1]
        if waited >= OFF_CPU_S and waited > ran:
            self._release(waited)

    def watching(self, answer: Callable[..., None]) -> Callable[..., None]:
        """``answer`` (a server's answer to a batch of requests), watched."""

        def watched(*args: Any) -> None:
            try:
                answer(*args)
            finally:
                self.answered()

        return watched

    def _is_pinned(self) -> bool:
        if self.released or not self.start_cpus:
            return False
        now = _affinity()
        return now is not None and len(now) < len(self.start_cpus)

    def _release(self, waited: float) -> None:
        assert self.start_cpus is not None
        pinned_to = sorted(_affinity() or ())
        self.released = True
        self._stat.close()
        try:
            os.sched_setaffinity(0, self.start_cpus)
        except OSError as exc:
            log.info("sim instance %d: could not take its CPUs back (%s); it stays pinned", self.instance, exc)
            return
        log.info(
            "sim instance %d waited %.1f ms for its CPU %s over its last %d answers (a busy neighbour): "
            "it runs on CPUs %s from now on",
            self.instance,
            waited * 1e3,
            pinned_to,
            WINDOW,
            sorted(self.start_cpus),
        )


__all__ = ["OFF_CPU_S", "WINDOW", "PinRelease", "SchedStat"]
