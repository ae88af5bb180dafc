"""Timing helper the throughput benchmarks share. Runs in the agent process (benchmarks only)."""

from __future__ import annotations

import time
from collections.abc import Callable


def timed(step: Callable[[int], None], duration: float, warmup: int = 50) -> float:
    """Calls per second of ``step(i)`` over ``duration`` seconds, after ``warmup`` calls."""
    for i in range(warmup):
        step(i)
    calls = 0
    start = time.perf_counter()
    end = start + duration
    now = start
    while now < end:
        for _ in range(20):
            step(calls)
            calls += 1
        now = time.perf_counter()
    return calls / (now - start)
