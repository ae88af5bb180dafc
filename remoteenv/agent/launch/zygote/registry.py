"""This agent process's zygotes: one per sim environment, reused by every launch.

Runs in the agent process. :func:`zygote_for` hands the launcher the zygote
for sims that run with a given environment (and working directory, where
``PYTHONPATH`` names a relative path; starting it on first use), or
None where none can be used: turned off (``REMOTEENV_ZYGOTE=0`` or
``Launcher(zygote=False)``), not Linux with pidfds (Linux 5.3+), or a zygote
for that environment failed before. A zygote lives as long as this process
(it exits with it), except that one with no sim left and unused for
:data:`IDLE_S` is closed when another is asked for. A process forked from
this one (``multiprocessing``'s fork) starts with no zygotes: those belong
to its parent, and sims it forks would not follow this process out.
:func:`prestart` starts one ahead of the first launch.
"""

from __future__ import annotations

import os
import socket
import sys
import threading
import time
from collections.abc import Mapping

from remoteenv.agent.launch.zygote.process import Zygote

#: The environment variable that turns zygotes off (``0``, ``false``, ``no`` or ``off``).
SWITCH = "REMOTEENV_ZYGOTE"
#: Seconds an unused zygote with no sims stays before another launch closes it.
IDLE_S = 60.0

_lock = threading.Lock()
_zygotes: dict[tuple[str, tuple[tuple[str, str], ...]], Zygote] = {}
_failed: set[tuple[str, tuple[tuple[str, str], ...]]] = set()


def enabled() -> bool:
    """Whether zygotes may be used here: the switch allows it and the platform has what they need."""
    if os.environ.get(SWITCH, "1").strip().lower() in {"0", "false", "no", "off"}:
        return False
    return sys.platform.startswith("linux") and hasattr(os, "pidfd_open") and hasattr(socket, "send_fds")


def zygote_for(env: Mapping[str, str], scene: str | None = None) -> Zygote | None:
    """The zygote for sims that run with the environment ``env``: started now
    (preloading ``scene``'s imports) if there is none, None if zygotes are off
    here or one failed for ``env`` before."""
    if not enabled():
        return None
    key = _key(env)
    with _lock:
        if key in _failed:
            return None
        _close_idle(keep=key)
        zygote = _zygotes.get(key)
        if zygote is not None and zygote.alive:
            return zygote
        try:
            zygote = Zygote(env, [scene] if scene else [])
        except OSError:
            _failed.add(key)
            return None
        _zygotes[key] = zygote
        return zygote


def failed(env: Mapping[str, str]) -> None:
    """Record that the zygote for ``env`` could not start its sims: none is tried again for it."""
    key = _key(env)
    with _lock:
        _failed.add(key)
        zygote = _zygotes.pop(key, None)
    if zygote is not None and not zygote.busy():
        zygote.close()


def prestart(env: Mapping[str, str], scene: str | None = None) -> bool:
    """Start the zygote for ``env`` now, so that the first launch finds it
    ready; returns at once (False where zygotes are off)."""
    return zygote_for(env, scene) is not None


def close_all() -> None:
    """Close every zygote of this process (their running sims see their parent go and stop)."""
    with _lock:
        zygotes = list(_zygotes.values())
        _zygotes.clear()
    for zygote in zygotes:
        zygote.close()


def _key(env: Mapping[str, str]) -> tuple[str, tuple[tuple[str, str], ...]]:
    """What a zygote's sims would see differently from a plain start's if it
    changed: the interpreter, the environment and, where ``PYTHONPATH`` has a
    relative or empty entry (which an interpreter resolves against its working
    directory when it starts), our working directory."""
    items = sorted(env.items())
    if any(not os.path.isabs(entry) for entry in env.get("PYTHONPATH", "/").split(os.pathsep)):
        try:
            items.append(("", os.getcwd()))  # no environment variable has an empty name
        except OSError:
            pass
    return sys.executable, tuple(items)


def _close_idle(keep: tuple[str, tuple[tuple[str, str], ...]]) -> None:
    now = time.monotonic()
    for key, zygote in list(_zygotes.items()):
        if key == keep:
            continue
        if not zygote.alive or (now - zygote.last_used > IDLE_S and not zygote.busy()):
            del _zygotes[key]
            zygote.close()


def _forget_after_fork() -> None:
    """In a child forked from this process: drop the parent's zygotes without
    stopping them (their channels are closed here only)."""
    global _lock
    _lock = threading.Lock()
    for zygote in _zygotes.values():
        zygote.abandon()
    _zygotes.clear()
    _failed.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_after_fork)

__all__ = ["IDLE_S", "SWITCH", "close_all", "enabled", "failed", "prestart", "zygote_for"]
