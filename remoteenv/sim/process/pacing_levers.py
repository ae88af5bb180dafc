"""Levers a real-time sim process can pull to keep its pacing on a busy host.

Runs in the sim process (``python <scene script> --rt-priority ...``, see
:mod:`remoteenv.sim.scene_main`); ``python -m remoteenv bench --real-time
--rt-levers`` measures what each one buys. All are off by default:

- real-time scheduling (``SCHED_FIFO`` at a priority, Linux): the paced
  process preempts ordinary ones, so a CPU hog beside it cannot delay its
  wake-ups. Needs root or ``CAP_SYS_NICE`` (or an ``RLIMIT_RTPRIO``); when
  refused the process logs a warning (``remoteenv.sim`` logger, see
  :mod:`remoteenv.sim.process.log`) and runs on with normal priority.
  A FIFO process that never sleeps would starve its CPU: the server loop
  sleeps between deadlines, and spins only within the spin window.
- CPU affinity: pin the process to given CPUs (e.g. away from the agent's).
- garbage collector: ``freeze`` moves every object alive after start-up out
  of the collector's view (:func:`gc.freeze`) and makes collections rarer,
  so a collection seldom lands in the paced loop; ``off`` disables automatic
  collection (the sim's steady state allocates no cycles; use with care).
- the spin window: how long before each deadline the loop stops sleeping and
  spins (:data:`remoteenv.sim.serving.sim_server.DEADLINE_SPIN_S` by default), which
  absorbs the kernel's wake-up latency at the cost of CPU time.
"""

from __future__ import annotations

import gc
import logging
import os
from collections.abc import Sequence

log = logging.getLogger(__name__)

GC_MODES = ("auto", "freeze", "off")
#: Generation-0 threshold with ``gc="freeze"`` (CPython's default is 2000 since 3.13, 700 before).
FROZEN_GC_THRESHOLD = 50_000


def set_realtime_priority(priority: int) -> bool:
    """Run this process under ``SCHED_FIFO`` at ``priority`` (1..99); False, with
    a logged warning, where the OS refuses or lacks it."""
    if not hasattr(os, "sched_setscheduler"):
        log.warning("real-time scheduling is not available on this OS; normal priority")
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        log.warning(
            "SCHED_FIFO priority %d refused (needs root, CAP_SYS_NICE or an RLIMIT_RTPRIO of at least "
            "that); running with normal priority",
            priority,
        )
        return False
    return True


def pin_cpus(cpus: Sequence[int]) -> None:
    """Run this process on ``cpus`` only."""
    os.sched_setaffinity(0, set(cpus))


def tame_gc(mode: str) -> None:
    """``auto``: leave the collector alone; ``freeze``: freeze what exists and
    collect rarely; ``off``: no automatic collection."""
    if mode not in GC_MODES:
        raise ValueError(f"gc mode must be one of {GC_MODES}, got {mode!r}")
    if mode == "auto":
        return
    gc.collect()
    gc.freeze()
    if mode == "off":
        gc.disable()
    else:
        _, second, third = gc.get_threshold()
        gc.set_threshold(FROZEN_GC_THRESHOLD, second, third)


def apply_levers(priority: int = 0, cpus: Sequence[int] | None = None, gc_mode: str = "auto") -> list[str]:
    """Pull the levers asked for; the list of those in effect (for the log)."""
    on = []
    if cpus:
        pin_cpus(cpus)
        on.append(f"cpus {sorted(set(cpus))}")
    if priority and set_realtime_priority(priority):
        on.append(f"SCHED_FIFO {priority}")
    if gc_mode != "auto":
        tame_gc(gc_mode)
        on.append(f"gc {gc_mode}")
    return on


__all__ = ["FROZEN_GC_THRESHOLD", "GC_MODES", "apply_levers", "pin_cpus", "set_realtime_priority", "tame_gc"]
