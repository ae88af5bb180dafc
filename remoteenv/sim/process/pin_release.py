"""A pinned sim that a busy neighbour keeps off its CPU takes its other CPUs back.

Runs in the sim process, in lock step. The agent's vector env pins each of
its one-thread sims to a CPU of its own (``place_sims="auto"``, see
:mod:`remoteenv.agent.vector.sim_placement`): side by side on a quiet
machine they step faster so. But a CPU that another program keeps busy (a
CPU hog, another job, a learner running beside the sims) is shared in time
slices of milliseconds, and a pinned sim cannot move to a CPU that is free:
beside one CPU hog, pinned sims stepped 2.4–4.7× slower than sims left to
the OS (docs/performance-history.md). So every :data:`WINDOW` answers a pinned sim
reads from the kernel how long its serving thread waited, runnable, for a
CPU (``run_delay`` in ``/proc/<pid>/task/<tid>/schedstat``, which counts
the waits after each wake-up too) against how long it ran: when it waited at
least :data:`OFF_CPU_S` seconds in that window, and longer than it ran, it
takes back the CPUs it served on before it was pinned (logged at info).

A neighbour may leave (a job ends): :data:`RETRY_S` seconds after a release
the sim tries its CPU again, pinned as the agent had pinned it, and watched
as before. A trial that a busy neighbour ends within :data:`TRIAL_WINDOWS`
windows releases it again and doubles the time to the next trial (at most
:data:`MAX_RETRY_S`); a trial that lasts them resets that time. A sim whose
CPUs someone else changed meanwhile is left as it is. Where the kernel does
not say, nothing changes.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

#: Answers per look: how often a sim checks whether it is pinned and how long it waited for its CPU.
WINDOW = 32
#: Seconds a pinned sim must have waited for its CPU within a window to take its CPUs back.
OFF_CPU_S = 0.010
#: Seconds from a release to the first trial of the pinned CPUs again.
RETRY_S = 2.0
#: Longest time between trials (seconds), however often busy neighbours ended them.
MAX_RETRY_S = 64.0
#: Windows a trial must last, pinned, for its neighbour to count as gone.
TRIAL_WINDOWS = 4


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
    read of the thread's ``schedstat``; while released, one clock reading).
    ``clock``: monotonic seconds (for tests).
    """

    def __init__(
        self, instance: int, stat: SchedStat | None = None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.instance = instance
        #: The CPUs the sim may run on before anyone pins it (None: the OS cannot tell).
        self.start_cpus = _affinity()
        #: True while the sim has taken its CPUs back (until a trial pins it again).
        self.released = False
        #: The CPUs it was pinned to when it was last released (None: it will not try them again).
        self.pinned_cpus: set[int] | None = None
        self._stat = stat if stat is not None else SchedStat()
        self._clock = clock
        self._count = 0
        self._last: tuple[float, float] | None = None
        self._wait_s = RETRY_S
        self._retry_at = 0.0
        self._trial_left = 0

    def answered(self) -> None:
        """One more batch of answers; every :data:`WINDOW`, judge the window."""
        self._count += 1
        if self._count < WINDOW:
            return
        self._count = 0
        if self.released:
            if self.pinned_cpus is not None and self._clock() >= self._retry_at:
                self._pin_again()
            return
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
        elif self._trial_left:
            self._trial_left -= 1
            if not self._trial_left:  # the neighbour is gone: a later one is tried again soon
                self._wait_s = RETRY_S

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
        pinned = _affinity()
        self.released = True
        if self._trial_left:  # a trial the neighbour ended: wait longer before the next
            self._wait_s = min(self._wait_s * 2, MAX_RETRY_S)
        self._trial_left = 0
        if not self._move(self.start_cpus, "pinned"):
            return
        self.pinned_cpus = pinned
        self._retry_at = self._clock() + self._wait_s
        log.info(
            "sim instance %d waited %.1f ms for its CPU %s over its last %d answers (a busy neighbour): "
            "it runs on CPUs %s, and tries its CPU again in %.0f s",
            self.instance,
            waited * 1e3,
            sorted(pinned or ()),
            WINDOW,
            sorted(self.start_cpus),
            self._wait_s,
        )

    def _pin_again(self) -> None:
        assert self.pinned_cpus is not None
        if _affinity() != self.start_cpus:  # someone else placed it meanwhile: theirs to keep
            self._give_up()
            return
        if not self._move(self.pinned_cpus, "unpinned"):
            return
        self.released = False
        self._last = None  # the first window pinned again only reads where the figures stand
        self._trial_left = TRIAL_WINDOWS
        log.info("sim instance %d tries its CPU %s again", self.instance, sorted(self.pinned_cpus))

    def _move(self, cpus: set[int], otherwise: str) -> bool:
        """Run on ``cpus`` from now on; False (logged, and no more trials) if the OS refuses."""
        try:
            os.sched_setaffinity(0, cpus)
        except OSError as exc:
            log.info(
                "sim instance %d could not move to CPUs %s (%s): it stays %s",
                self.instance,
                sorted(cpus),
                exc,
                otherwise,
            )
            self._give_up()
            return False
        return True

    def _give_up(self) -> None:
        self.pinned_cpus = None
        self._stat.close()


__all__ = ["MAX_RETRY_S", "OFF_CPU_S", "RETRY_S", "TRIAL_WINDOWS", "WINDOW", "PinRelease", "SchedStat"]
