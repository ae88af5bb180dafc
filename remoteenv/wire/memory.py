"""How much memory this machine has left, and whether a number of worlds fits in it.

Used on both sides: a sim process checks, before building the rest of its
worlds, that they fit (:func:`worlds_problem`, from the footprint of one it
built); the benchmarks check their cases before building any contender. The
figures come from Linux's ``/proc`` (``MemAvailable``, this process's resident
set); where they cannot be read nothing is refused.
"""

from __future__ import annotations

import os

#: Share of the machine's memory a request may not take (what the system,
#: the learner and everything else keep).
RESERVE_FRACTION = 0.2


def available_bytes() -> int | None:
    """``MemAvailable`` minus :data:`RESERVE_FRACTION` of ``MemTotal`` (bytes, >= 0),
    or None where ``/proc/meminfo`` cannot be read."""
    fields: dict[str, int] = {}
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                name, _, rest = line.partition(":")
                parts = rest.split()
                if name in ("MemAvailable", "MemTotal") and parts:
                    fields[name] = int(parts[0]) * 1024
    except (OSError, ValueError):
        return None
    if len(fields) != 2:
        return None
    return max(0, fields["MemAvailable"] - int(RESERVE_FRACTION * fields["MemTotal"]))


def resident_bytes() -> int | None:
    """This process's resident set (bytes), or None where it cannot be read."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def format_bytes(n: float) -> str:
    """``n`` bytes for a message: ``"45 MB"``, ``"4.4 TB"``."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit in ("B", "kB") or abs(n) >= 100 else f"{n:.1f} {unit}"
        n /= 1000
    raise AssertionError("unreachable")


def worlds_that_fit(each_bytes: int, available: int) -> int:
    """How many more worlds of ``each_bytes`` fit in ``available`` bytes."""
    return available // max(1, each_bytes)


def worlds_problem(count: int, each_bytes: int, what: str, fix: str) -> str | None:
    """Why ``count`` more worlds of ``each_bytes`` each do not fit in this
    machine's available memory (one line: the figures and ``fix``, where the
    placeholder ``{fit}`` is the count that fits), or None if they fit or the
    memory cannot be read. ``what`` names the worlds."""
    available = available_bytes()
    need = count * each_bytes
    if available is None or need <= available:
        return None
    fit = worlds_that_fit(each_bytes, available)
    return (
        f"{what}: {count} worlds of about {format_bytes(each_bytes)} each need about {format_bytes(need)}, "
        f"more than the {format_bytes(available)} this machine has available (keeping "
        f"{RESERVE_FRACTION:.0%} of its memory free): {fix.format(fit=fit)}"
    )


__all__ = [
    "RESERVE_FRACTION",
    "available_bytes",
    "format_bytes",
    "resident_bytes",
    "worlds_problem",
    "worlds_that_fit",
]
