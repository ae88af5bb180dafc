"""Private dirs that go when this process goes, however it ends.

Runs in the agent process. Whoever creates a private dir (a launcher's
socket/log dir, the latency study's policy dir) registers it here with
:func:`watch_dir` right after creating it and :func:`forget_dir` after
removing it. The first registration starts this process's dir reaper
(:mod:`remoteenv.agent.launch.dir_reaper_main`, a standard-library-only
process started by path), which removes every dir still registered within
milliseconds of this process's end: SIGKILL and a pool's ``terminate()``
included, before any sim exists too. A process forked from this one starts
with no reaper and no dirs: its parent's dirs are its parent's.
"""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

#: The reaper's script, run by path with ``python -I -S``.
REAPER_SCRIPT = str(Path(__file__).with_name("dir_reaper_main.py"))

_lock = threading.Lock()
_dirs: set[str] = set()
#: The reaper's pid. No ``Popen``: one still running when the interpreter
#: ends warns (ResourceWarning), and the reaper is meant to outlive us.
_reaper: int | None = None
_write_fd = -1


def watch_dir(path: str) -> None:
    """Remove ``path`` (a dir this process created) when this process ends, if it is still there."""
    path = os.path.abspath(path)
    with _lock:
        _dirs.add(path)
        _send(b"+" + os.fsencode(path) + b"\0")


def forget_dir(path: str) -> None:
    """``path`` has been removed (or handed over): the reaper leaves it alone."""
    path = os.path.abspath(path)
    with _lock:
        if path in _dirs:
            _dirs.discard(path)
            _send(b"-" + os.fsencode(path) + b"\0")


def reaper_pid() -> int | None:
    """The pid of this process's reaper, None before the first registration."""
    return _reaper


def _send(record: bytes) -> None:
    """Write ``record`` to the reaper, starting one (with every dir still registered) if none runs."""
    global _reaper, _write_fd
    for _attempt in range(2):
        if _write_fd < 0 or not _reaper_running():
            if not _start():
                return
            record = b"".join(b"+" + os.fsencode(p) + b"\0" for p in sorted(_dirs))
            if not record:
                return
        try:
            os.write(_write_fd, record)  # small records: atomic on a pipe
            return
        except OSError:
            _close()


def _reaper_running() -> bool:
    """Whether our reaper runs (one that ended is reaped here)."""
    global _reaper
    if _reaper is None:
        return False
    try:
        pid, _status = os.waitpid(_reaper, os.WNOHANG)
    except ChildProcessError:  # reaped by someone else
        pid = _reaper
    if pid == 0:
        return True
    _reaper = None
    return False


def _start() -> bool:
    global _reaper, _write_fd
    _close()
    read_end, write_end = os.pipe()  # both close-on-exec: only the reaper gets the read end
    try:
        _reaper = os.posix_spawn(
            sys.executable,
            [sys.executable, "-I", "-S", REAPER_SCRIPT, str(os.getpid())],
            os.environ,
            file_actions=[
                (os.POSIX_SPAWN_DUP2, read_end, 0),
                (os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0),
                (os.POSIX_SPAWN_OPEN, 2, os.devnull, os.O_WRONLY, 0),
            ],
            setsid=True,  # a signal to our process group is not for it: it follows us out
        )
    except OSError:
        os.close(write_end)
        return False
    finally:
        os.close(read_end)
    _write_fd = write_end
    return True


def _close() -> None:
    global _write_fd
    if _write_fd >= 0:
        try:
            os.close(_write_fd)
        except OSError:
            pass
        _write_fd = -1


def _forget_after_fork() -> None:
    """In a child forked from this process: the parent's reaper and dirs are the parent's."""
    global _lock, _reaper
    _lock = threading.Lock()
    _close()
    _reaper = None
    _dirs.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_after_fork)

__all__ = ["REAPER_SCRIPT", "forget_dir", "reaper_pid", "watch_dir"]
