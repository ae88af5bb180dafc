"""When to busy-wait for the peer instead of sleeping (both processes use it).

On a virtual machine a blocking wait costs tens of microseconds per message:
the sleeping CPU must be woken by an interrupt. When the peer answers within
a short window, waiting hot (polling without sleeping) is several times faster
and costs only that window's CPU. :class:`HotWait` decides adaptively: it
waits hot while recent waits were shorter than the window, stops when the
peer is slow (a policy that thinks, many envs to gather), and probes again
now and then.
"""

from __future__ import annotations

import os
import time

#: Re-try waiting hot once every this many cold waits.
_PROBE_EVERY = 32

#: Give the CPU to another runnable process, if any, while busy-waiting.
yield_cpu = getattr(os, "sched_yield", lambda: None)


class HotWait:
    """Adaptive busy-wait policy for one channel.

    Args:
        window_s: longest busy-wait in seconds; 0 disables waiting hot. It is
            also disabled on a single-CPU machine (spinning would starve the
            peer) and when the environment variable ``REMOTEENV_NO_SPIN`` is set.
    """

    def __init__(self, window_s: float) -> None:
        if (os.cpu_count() or 1) < 2 or os.environ.get("REMOTEENV_NO_SPIN"):
            window_s = 0.0
        self.window_s = window_s
        self._last_wait_s = 0.0
        self._cold = 0
        #: perf_counter() time the current wait started (set by the caller).
        self.since = time.perf_counter()

    def worth_it(self) -> bool:
        """Whether the next wait should start hot."""
        if not self.window_s:
            return False
        if self._last_wait_s <= self.window_s:
            return True
        self._cold += 1
        if self._cold >= _PROBE_EVERY:
            self._cold = 0
            return True
        return False

    def waited(self, seconds: float) -> None:
        """Record how long the last wait for the peer took."""
        self._last_wait_s = seconds
