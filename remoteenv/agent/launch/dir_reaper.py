"""Private dirs that go when this process goes, however it ends.

Runs in the agent process. Whoever creates a private dir (a launcher's
socket/log dir, the latency study's policy dir) registers it here with
:func:`watch_dir` right after creating it and :func:`forget_dir` after
removing it. The first registration starts this process's dir reaper
(:mod:`remoteenv.agent.launch.dir_reaper_main`, a standard-library-only
process started by path), which removes every dir still registered within
milliseconds of this process's end: SIGKILL and a pool's ``terminate()``
included, before any sim exists too. It removes only the dir this process
made (its identity is registered with it), never through a symlink
(:mod:`remoteenv.wire.files.owned_dirs`). The pipe to it is non-blocking and
what it has not read yet is held here, bounded (:data:`MAX_BACKLOG`), and
written by a thread as the pipe takes it again: a stopped reaper never stops
this process. A process forked from this one starts
with no reaper and no dirs: its parent's dirs are its parent's.
"""

from __future__ import annotations

import os
import select
import sys
import threading
import warnings
from pathlib import Path

from remoteenv.wire.files.owned_dirs import DirId, format_id, identity

#: The reaper's script, run by path with ``python -I -S``.
REAPER_SCRIPT = str(Path(__file__).with_name("dir_reaper_main.py"))
#: Most bytes of records held back for a reaper that is not reading its pipe
#: (stopped, say); beyond that they are replaced by one resync of the dirs
#: registered now, so what is held is bounded by the dirs alive, not by calls.
MAX_BACKLOG = 64 * 1024

_lock = threading.Lock()
#: Registered dirs: path -> identity of the dir this process made there.
_dirs: dict[str, DirId] = {}
#: The reaper's pid. No ``Popen``: one still running when the interpreter
#: ends warns (ResourceWarning), and the reaper is meant to outlive us.
_reaper: int | None = None
_write_fd = -1
#: Records not yet written to the reaper's pipe (the write end is non-blocking).
_backlog = bytearray()
#: Whether the bytes written so far end inside a record (the backlog then starts with its rest).
_mid_record = False
_warned = False
#: The thread writing the backlog once the pipe takes it again (None: no backlog).
_drainer: threading.Thread | None = None


def watch_dir(path: str) -> DirId | None:
    """Remove ``path`` (a dir this process has just created) when this process
    ends, if that dir is still there; returns its identity
    (:func:`~remoteenv.wire.files.owned_dirs.identity`), None (and nothing
    registered) if ``path`` is not a dir of this user.

    Never blocks: a reaper that does not read (stopped) gets the records later,
    and costs one warning."""
    path = os.path.abspath(path)
    dir_id = identity(path)
    if dir_id is None:
        return None
    with _lock:
        _dirs[path] = dir_id
        _send(_record(path, dir_id))
    return dir_id


def forget_dir(path: str) -> None:
    """``path`` has been removed (or handed over): the reaper leaves it alone."""
    path = os.path.abspath(path)
    with _lock:
        if _dirs.pop(path, None) is not None:
            _send(b"-" + os.fsencode(path) + b"\0")


def reaper_pid() -> int | None:
    """The pid of this process's reaper, None before the first registration."""
    return _reaper


def _record(path: str, dir_id: DirId) -> bytes:
    return b"+" + format_id(dir_id).encode() + b":" + os.fsencode(path) + b"\0"


def _state() -> bytes:
    """Records that make a reaper's dirs those registered now."""
    return b"=\0" + b"".join(_record(p, i) for p, i in sorted(_dirs.items()))


def _send(record: bytes) -> None:
    """Queue ``record`` for the reaper and write what its pipe takes now, starting
    a reaper (told every dir registered) if none runs or its pipe broke."""
    for _attempt in range(2):
        if _write_fd < 0 or not _reaper_running():
            if not _start():
                return
            record = _state()
        _queue(record)
        if _flush():
            return


def _queue(record: bytes) -> None:
    global _backlog
    _backlog += record
    if len(_backlog) > MAX_BACKLOG:
        # What is owed is the current set of dirs: say it once instead (after
        # the rest of a record cut by a partial write, which the reaper needs first).
        keep = bytes(_backlog[: _backlog.index(b"\0") + 1]) if _mid_record else b""
        resync = keep + _state()
        if len(resync) < len(_backlog):
            _backlog = bytearray(resync)


def _flush() -> bool:
    """Write what the pipe takes without waiting; False if the pipe broke (the reaper is gone)."""
    global _mid_record, _warned
    while _backlog:
        try:
            written = os.write(_write_fd, _backlog)
        except BlockingIOError:
            _start_drainer()
            if not _warned:
                _warned = True
                warnings.warn(
                    f"remoteenv: the dir reaper (pid {_reaper}) is not reading its pipe (stopped?); "
                    "its records wait in this process, and a private dir may outlive a crash of it",
                    RuntimeWarning,
                    stacklevel=5,
                )
            return True
        except OSError:
            _close()
            return False
        _mid_record = _backlog[written - 1] != 0
        del _backlog[:written]
    return True


def _start_drainer() -> None:
    global _drainer
    if _drainer is None:
        _drainer = threading.Thread(target=_drain, name="remoteenv-dir-reaper-writer", daemon=True)
        _drainer.start()


def _drain() -> None:
    """Write the backlog as the reaper's pipe takes it (never holding the lock while waiting)."""
    global _drainer
    poller = select.poll()
    while True:
        with _lock:
            fd = _write_fd
            if not _backlog or fd < 0:
                _drainer = None
                return
        poller.register(fd, select.POLLOUT)
        poller.poll(1000)
        poller.unregister(fd)
        with _lock:
            if fd == _write_fd:
                _flush()


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
    global _reaper, _write_fd, _mid_record
    _close()
    _backlog.clear()
    _mid_record = False
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
    os.set_blocking(write_end, False)  # the agent never waits on its reaper
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
    global _lock, _reaper, _mid_record, _warned, _drainer
    _lock = threading.Lock()
    _drainer = None
    _close()
    _reaper = None
    _dirs.clear()
    _backlog.clear()
    _mid_record = _warned = False


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_after_fork)

__all__ = ["MAX_BACKLOG", "REAPER_SCRIPT", "forget_dir", "reaper_pid", "watch_dir"]
