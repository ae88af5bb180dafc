"""Whether the host ran at full speed while a contender was timed: a probe between slots.

Benchmarks only (``bench --train-loop``). On a virtual machine the host's
own speed comes and goes: for minutes at a time every CPU of the guest can
run at half its speed or less (measured here: a fixed loop taking 13-15 ms
where it takes 6-7 ms at best), with no sign in the guest's load average
and, in some of those minutes, little in its steal time (which the run
reports beside: :mod:`~remoteenv.benchmarks.harness.host_steal`). A ratio
of two contenders timed one after the other is then a ratio of two hosts.
:class:`HostSpeed` times a fixed piece of pure-Python work on each CPU the
benchmark may use (:func:`probe_s`, the slowest CPU's time) before the first
slot and after every slot, while no contender runs; a slot's *host speed* is
the run's fastest probe over the slower of the probes either side of it
(1.0: as fast as the host was at its best in this run). A slot at :data:`FULL_SPEED` or
more ran on a host at full speed, as far as the probes can tell.
"""

from __future__ import annotations

import os
import time

#: Iterations of the probe's loop: about 6 ms on one CPU of the reference machine at full speed.
PROBE_LOOP = 200_000
#: A slot whose probes ran at least this fraction of the run's fastest probe ran at full speed.
FULL_SPEED = 0.85


def _loop() -> float:
    """Seconds for :data:`PROBE_LOOP` additions in the interpreter."""
    start = time.perf_counter()
    total = 0
    for i in range(PROBE_LOOP):
        total += i
    return time.perf_counter() - start


def probe_s() -> float:
    """Seconds the slowest CPU this process may use takes for the probe's loop
    (the calling thread moved to each in turn, then given its CPUs back)."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity here: the loop where it runs
        return _loop()
    slowest = 0.0
    try:
        for cpu in cpus:
            os.sched_setaffinity(0, {cpu})
            slowest = max(slowest, _loop())
    finally:
        os.sched_setaffinity(0, cpus)
    return slowest


class HostSpeed:
    """The probes of one run, one before the first slot and one after each
    (:meth:`after_slot`), and each slot's host speed once the run is over."""

    def __init__(self) -> None:
        self._probes = [probe_s()]

    def after_slot(self) -> tuple[int, int]:
        """Probe after the slot just timed; that slot's probes, before and
        after it, as indices for :meth:`speed`."""
        self._probes.append(probe_s())
        return len(self._probes) - 2, len(self._probes) - 1

    @property
    def fastest_s(self) -> float:
        """The run's fastest probe (seconds): how fast the host was at its best."""
        return min(self._probes)

    def speed(self, probes: tuple[int, int]) -> float:
        """A slot's host speed: the run's fastest probe over the slower of its two."""
        before, after = probes
        return self.fastest_s / max(self._probes[before], self._probes[after])


__all__ = ["FULL_SPEED", "PROBE_LOOP", "HostSpeed", "probe_s"]
