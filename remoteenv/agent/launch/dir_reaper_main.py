"""The dir reaper: a tiny process that removes an agent's private dirs once the agent is gone.

Started by the agent (:mod:`remoteenv.agent.launch.dir_reaper`) as a script
(``python -I -S dir_reaper_main.py AGENT_PID``) that imports only the
standard library, in a session of its own, with its stdin the read end of a
pipe whose write end only the agent holds. The agent writes a record for
each private dir it creates (``+<dev>:<ino>:<path>\\0``, the dir's identity
and path) and removes (``-<path>\\0``); ``=\\0`` forgets every dir (the agent
then names those registered now, after its pipe was full).

It watches the agent through a pidfd (Linux 5.3+; else the end of file on
its stdin, which comes when the agent's process ends). Once the agent is
gone, however it ended (SIGKILL included, before any sim existed), it reads
what is left in the pipe and removes every dir still registered, then exits:
only the dir with the registered identity, through descriptors, opening
nothing that could block (a FIFO planted at the path is refused, not
opened) and following no symlink (:mod:`remoteenv.wire.files.owned_dirs`,
loaded by path: this script imports nothing else of remoteenv).
The sims' own orphan guards still end the sims and tidy their files; this
process covers the moments before a sim exists (the private dir made, the
zygote still importing) and dirs no sim owns.
"""

from __future__ import annotations

import os
import select
import signal
import sys
from types import ModuleType

#: Longest record accepted (a path longer than any the kernel takes).
MAX_RECORD = 8192


def _load_owned_dirs() -> ModuleType:
    """:mod:`remoteenv.wire.files.owned_dirs`: imported, or loaded from its file when
    this script runs by path (``-I -S``: the package is not importable then)."""
    try:
        from remoteenv.wire.files import owned_dirs

        return owned_dirs
    except ImportError:
        import importlib.util

        here = os.path.dirname(os.path.abspath(__file__))
        path = os.path.join(here, os.pardir, os.pardir, "wire", "files", "owned_dirs.py")
        spec = importlib.util.spec_from_file_location("remoteenv_owned_dirs", path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module


owned_dirs = _load_owned_dirs()


def parse(buffer: bytes, dirs: dict[str, tuple[int, int]]) -> bytes:
    """Apply the complete records of ``buffer`` to ``dirs`` (path -> identity);
    return the incomplete rest."""
    *records, rest = buffer.split(b"\0")
    for record in records:
        kind = record[:1]
        if kind == b"+":
            dev, _, rest_of = record[1:].partition(b":")
            ino, _, raw_path = rest_of.partition(b":")
            dir_id = owned_dirs.parse_id(f"{dev.decode(errors='replace')}:{ino.decode(errors='replace')}")
            path = os.fsdecode(raw_path)
            if dir_id is not None and os.path.isabs(path):
                dirs[path] = dir_id
        elif kind == b"-":
            dirs.pop(os.fsdecode(record[1:]), None)
        elif kind == b"=":
            dirs.clear()
    return b"" if len(rest) > MAX_RECORD else rest


def _pidfd(pid: int) -> int:
    try:
        return os.pidfd_open(pid)
    except (OSError, AttributeError):
        return -1


def reap(agent_pid: int, stdin: int = 0) -> int:
    """Watch ``agent_pid`` (our parent) and the records on ``stdin``; remove the dirs once it is gone."""
    dirs: dict[str, tuple[int, int]] = {}
    buffer = b""
    agent = _pidfd(agent_pid)
    if agent >= 0 and os.getppid() != agent_pid:  # checked after opening: the pidfd cannot name another
        os.close(agent)
        agent = -2  # gone before we could watch it
    poller = select.poll()
    poller.register(stdin, select.POLLIN | select.POLLHUP)
    if agent >= 0:
        poller.register(agent, select.POLLIN)
    open_stdin = True
    while agent != -2:
        fds = {fd for fd, _ in poller.poll()}
        if agent >= 0 and agent in fds:
            break
        if stdin in fds and open_stdin:
            data = os.read(stdin, 65536)
            if data:
                buffer = parse(buffer + data, dirs)
                continue
            open_stdin = False  # every writer closed it: the agent is ending
            poller.unregister(stdin)
            if agent < 0:
                break
    if open_stdin:  # what the agent wrote just before it died
        os.set_blocking(stdin, False)
        while True:
            try:
                data = os.read(stdin, 65536)
            except BlockingIOError:
                break
            if not data:
                break
            buffer = parse(buffer + data, dirs)
    for path, dir_id in dirs.items():
        owned_dirs.remove_dir(path, dir_id)
    return 0


def _close_inherited() -> None:
    """Close every descriptor but 0-2 that the agent let us inherit: we outlive it
    by milliseconds and must not hold its sockets or pipes open meanwhile."""
    try:
        fds = [int(name) for name in os.listdir("/proc/self/fd")]
    except OSError:
        return
    for fd in fds:
        if fd > 2:
            try:
                os.close(fd)
            except OSError:
                pass


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C in a terminal is for the agent
    _close_inherited()
    return reap(int(argv[0]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
