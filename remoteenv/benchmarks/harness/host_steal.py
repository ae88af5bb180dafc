"""How much of a slot's time the virtual machine's host held the CPUs: steal time.

Benchmarks only (``bench --train-loop``). A virtual CPU the host gives to
another guest for a while runs nothing of this machine meanwhile; Linux
counts that time as *steal* in ``/proc/stat``. On the reference VM it
comes in bursts of seconds, up to a third of both CPUs' time, with quiet
minutes between (docs/performance-history.md, "The host's bursts of steal time"),
and a contender timed in a burst pays for it. :class:`HostSteal` reads the
counters before and after each slot; a slot's *steal share* is the fraction
of all CPUs' time in it that the host held (0.0: none). Where the OS has no
``/proc/stat`` it is None.
"""

from __future__ import annotations

#: The counters' file, a Linux ``proc(5)`` file.
PROC_STAT = "/proc/stat"
#: Index of the steal counter among the ``cpu`` line's numbers (user, nice, system, idle, iowait, irq, softirq, steal).
_STEAL = 7


def cpu_times(path: str = PROC_STAT) -> tuple[int, int] | None:
    """``(steal, total)`` of every CPU so far, in the kernel's ticks; None without ``path``.

    ``total`` is the sum of the line's first eight counters (guest time is
    counted within user and nice already, so it is left out)."""
    try:
        with open(path, encoding="ascii") as f:
            first = f.readline().split()
    except OSError:
        return None
    if len(first) < _STEAL + 2 or first[0] != "cpu":
        return None
    counters = [int(x) for x in first[1 : _STEAL + 2]]
    return counters[_STEAL], sum(counters)


def share(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float | None:
    """The steal share between two :func:`cpu_times` readings (None if either is None or no tick passed)."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return (after[0] - before[0]) / (after[1] - before[1])


class HostSteal:
    """The steal share of each slot: :meth:`start` before it, :meth:`stop` after it."""

    def __init__(self, path: str = PROC_STAT) -> None:
        self._path = path
        self._before: tuple[int, int] | None = None

    def start(self) -> None:
        """A slot begins."""
        self._before = cpu_times(self._path)

    def stop(self) -> float | None:
        """The slot just ended: the share of the CPUs' time the host held during it."""
        return share(self._before, cpu_times(self._path))


__all__ = ["PROC_STAT", "HostSteal", "cpu_times", "share"]
