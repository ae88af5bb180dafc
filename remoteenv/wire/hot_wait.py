"""When to busy-wait for the peer instead of sleeping (both processes use it).

On a virtual machine a blocking wait costs tens of microseconds per message:
the sleeping CPU must be woken by an interrupt. When the peer answers within
a short window, waiting hot (polling without sleeping) is several times faster
and costs only that window's CPU. :class:`HotWait` decides adaptively: it
waits hot while recent waits were shorter than the window, stops when the
peer is slow (a policy that thinks, many envs to gather), and probes again
now and then.

Waiting hot is only free while a CPU would otherwise sit idle. When more
tasks are runnable than there are CPUs (a CPU hog beside the training, more
sims than cores, the sims computing while the agent waits), a spinning
process takes the CPU that the peer or another worker needs. So a hot wait
starts, and goes on, only while the host's count of runnable tasks (Linux:
the fourth field of ``/proc/loadavg``, which counts the spinner itself) is
at most the number of CPUs; otherwise the wait sleeps at once.
"""

from __future__ import annotations

import os
import time

#: Re-try waiting hot once every this many cold waits.
_PROBE_EVERY = 32
#: Seconds between two looks at the host's run queue while spinning.
_CONTENTION_CHECK_S = 20e-6

#: Give the CPU to another runnable process, if any, while busy-waiting.
yield_cpu = getattr(os, "sched_yield", lambda: None)


def _open_loadavg() -> int | None:
    try:
        return os.open("/proc/loadavg", os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None


_LOADAVG_FD = _open_loadavg()
_HOST_CPUS = os.cpu_count() or 1


def runnable_tasks() -> int | None:
    """How many tasks the host has runnable right now, the caller included
    (None where the platform does not say)."""
    if _LOADAVG_FD is None:
        return None
    try:
        return int(os.pread(_LOADAVG_FD, 64, 0).split()[3].split(b"/")[0])
    except (OSError, ValueError, IndexError):
        return None


def spare_cpu() -> bool:
    """Whether spinning now takes no CPU another runnable task could use:
    runnable tasks (the caller counted) at most the host's CPUs. True where
    the platform does not report its run queue."""
    running = runnable_tasks()
    return running is None or running <= _HOST_CPUS


def _usable_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


class HotWait:
    """Adaptive busy-wait policy for one channel.

    Use :meth:`worth_it` before a wait and, if it says yes, :meth:`spin`
    between polls (it yields the CPU and says when to stop); report each
    wait's length with :meth:`waited`.

    Args:
        window_s: longest busy-wait in seconds; 0 disables waiting hot. It is
            also disabled when this process may use only one CPU (spinning
            would starve the peer) and when the environment variable
            ``REMOTEENV_NO_SPIN`` is set.
    """

    def __init__(self, window_s: float) -> None:
        if _usable_cpus() < 2 or os.environ.get("REMOTEENV_NO_SPIN"):
            window_s = 0.0
        self.window_s = window_s
        self._last_wait_s = 0.0
        self._cold = 0
        self._until = 0.0
        self._next_check = 0.0
        #: perf_counter() time the current wait started (set by the caller).
        self.since = time.perf_counter()

    def worth_it(self) -> bool:
        """Whether the next wait should start hot; if so, the spin's window starts now."""
        if not self.window_s:
            return False
        if self._last_wait_s > self.window_s:
            self._cold += 1
            if self._cold < _PROBE_EVERY:
                return False
            self._cold = 0
        if not spare_cpu():
            return False
        now = time.perf_counter()
        self._until = now + self.window_s
        self._next_check = now + _CONTENTION_CHECK_S
        return True

    def spin(self) -> bool:
        """Between two polls of a hot wait: yield the CPU to any task that
        shares it; False once the window is over or the host has no CPU to
        spare (then the caller sleeps)."""
        yield_cpu()
        now = time.perf_counter()
        if now >= self._until:
            return False
        if now >= self._next_check:
            self._next_check = now + _CONTENTION_CHECK_S
            return spare_cpu()
        return True

    def waited(self, seconds: float) -> None:
        """Record how long the last wait for the peer took."""
        self._last_wait_s = seconds
