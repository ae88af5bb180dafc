"""When to busy-wait for the peer instead of sleeping (both processes use it).

On a virtual machine a blocking wait costs tens of microseconds per message:
the sleeping CPU must be woken by an interrupt. When the peer answers within
a short window, waiting hot (polling without sleeping) is several times faster
and costs only that window's CPU. :class:`HotWait` decides adaptively: it
waits hot while recent waits were shorter than the window, stops when the
peer is slow (a policy that thinks, many envs to gather), and probes again
now and then.

Waiting hot is only free while the CPUs would otherwise sit idle. Beside a
program that keeps a CPU busy (a CPU hog, a training loop, another job), a
spinning process keeps the CPU that the peer or that program needs, and a
task that spins is never woken early the way a sleeping one is: when the
scheduler lets the other program run, the spinner waits out its whole time
slice (milliseconds), reply or not. The agent and its sims also take turns on
shared CPUs, but in short bursts (one request's work). So a spin that finds
itself kept off the CPU for longer than :data:`STALL_S` at once may have met a
busy neighbour: it stops, and every hot wait of the process sleeps instead
for a while, then tries again.

How long depends on how the stalls come. One stall alone is as often a
passing event: a garbage collection between two polls, the agent woken onto
the spinning sim's CPU until the scheduler moves one of them, the host taking
the virtual CPU away. After it the process cools down for
:data:`COOL_DOWN_MIN_S`. A busy neighbour stalls the next spin again, so each
stall within :data:`STALL_MEMORY_S` of the last doubles the cool-down, up to
:data:`COOL_DOWN_S`: beside a CPU hog the process reaches the long cool-down
after a handful of stalls and stays there while the hog runs.
"""

from __future__ import annotations

import os
import time

#: Re-try waiting hot once every this many cold waits.
_PROBE_EVERY = 32
#: A spin kept off the CPU this long (seconds) at once stalled: it may have met a busy neighbour.
STALL_S = 2.5e-3
#: Seconds every hot wait of the process sleeps after a stall that follows no
#: other within :data:`STALL_MEMORY_S`.
COOL_DOWN_MIN_S = 0.02
#: Longest cool-down (seconds): where stalls keep coming (a busy neighbour).
COOL_DOWN_S = 0.5
#: A stall this soon (seconds) after the last doubles the cool-down: more
#: than twice :data:`COOL_DOWN_S`, so that a neighbour that stalls the first
#: spin after every cool-down keeps the longest one.
STALL_MEMORY_S = 1.5

#: Give the CPU to another runnable process, if any, while busy-waiting.
yield_cpu = getattr(os, "sched_yield", lambda: None)


class _Neighbours:
    """Process-wide: until when hot waits sleep because a spin stalled, and
    how the last stalls came (see the module's docstring)."""

    cool_until = 0.0
    #: perf_counter() time of the last stall.
    last_stall = float("-inf")
    #: The last cool-down's length (seconds).
    cool_s = 0.0

    @classmethod
    def stalled(cls, now: float) -> None:
        """A spin stalled at ``now``: cool every hot wait of the process down."""
        if now - cls.last_stall < STALL_MEMORY_S:
            cls.cool_s = min(COOL_DOWN_S, max(COOL_DOWN_MIN_S, 2 * cls.cool_s))
        else:
            cls.cool_s = COOL_DOWN_MIN_S
        cls.last_stall = now
        cls.cool_until = now + cls.cool_s


def neighbours_busy() -> bool:
    """Whether this process's hot waits are cooling down now, after a spin
    stalled: something else (a CPU hog, another training run) holds its CPUs."""
    return time.perf_counter() < _Neighbours.cool_until


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
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
        patience: how many waits in a row must outlast the window before the
            next waits start cold (1: the last wait alone decides). A peer
            that is quick but now and then late (preempted, a garbage
            collection, a slow host's hiccup) keeps being waited for hot; a
            peer that is slow every time still turns the waits cold after
            ``patience`` of them.
    """

    def __init__(self, window_s: float, patience: int = 1) -> None:
        if usable_cpus() < 2 or os.environ.get("REMOTEENV_NO_SPIN"):
            window_s = 0.0
        if patience < 1:
            raise ValueError(f"patience counts waits and must be at least 1, got {patience}")
        self.window_s = window_s
        self.patience = patience
        self._last_wait_s = 0.0
        #: Waits in a row, the last one included, that outlasted the window.
        self._long_waits = 0
        self._cold = 0
        self._until = 0.0
        self._last_spin = 0.0
        #: perf_counter() time the current wait started (set by the caller).
        self.since = time.perf_counter()

    def allowed(self) -> bool:
        """Whether this policy may wait hot at all now (a window, and no
        cool-down after a stall); unlike :meth:`worth_it` it starts nothing."""
        return bool(self.window_s) and time.perf_counter() >= _Neighbours.cool_until

    def begin(self) -> bool:
        """Start a hot wait now if :meth:`allowed`, whatever the last waits
        took (for a wait the peer has said will be short); then :meth:`spin`."""
        if not self.allowed():
            return False
        now = time.perf_counter()
        self._until = now + self.window_s
        self._last_spin = now
        return True

    def worth_it(self) -> bool:
        """Whether the next wait should start hot; if so, the spin's window starts now."""
        if not self.window_s:
            return False
        if self._long_waits >= self.patience:
            self._cold += 1
            if self._cold < _PROBE_EVERY:
                return False
            self._cold = 0
        now = time.perf_counter()
        if now < _Neighbours.cool_until:
            return False
        self._until = now + self.window_s
        self._last_spin = now
        return True

    def spin(self) -> bool:
        """Between two polls of a hot wait: yield the CPU to any task that
        shares it; False once the window is over or the spin stalled (then
        the caller sleeps)."""
        yield_cpu()
        now = time.perf_counter()
        stalled = now - self._last_spin > STALL_S
        self._last_spin = now
        if stalled:
            _Neighbours.stalled(now)
            return False
        return now < self._until

    def waited(self, seconds: float) -> None:
        """Record how long the last wait for the peer took."""
        self._last_wait_s = seconds
        self._long_waits = self._long_waits + 1 if seconds > self.window_s else 0
