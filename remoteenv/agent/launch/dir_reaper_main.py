"""The dir reaper: a tiny process that removes an agent's private dirs once the agent is gone.

Started by the agent (:mod:`remoteenv.agent.launch.dir_reaper`) as a script
(``python -I -S dir_reaper_main.py AGENT_PID``) that imports only the
standard library, in a session of its own, with its stdin the read end of a
pipe whose write end only the agent holds. The agent writes a record for
each private dir it creates (``+<path>\\0``) and removes (``-<path>\\0``).

It watches the agent through a pidfd (Linux 5.3+; else the end of file on
its stdin, which comes when the agent's process ends). Once the agent is
gone, however it ended (SIGKILL included, before any sim existed), it reads
what is left in the pipe and removes every dir still registered, then exits.
The sims' own orphan guards still end the sims and tidy their files; this
process covers the moments before a sim exists (the private dir made, the
zygote still importing) and dirs no sim owns.
"""

from __future__ import annotations

import os
import select
import shutil
import signal
import sys

#: Longest record accepted (a path longer than any the kernel takes).
MAX_RECORD = 8192


def parse(buffer: bytes, dirs: set[str]) -> bytes:
    """Apply the complete records of ``buffer`` to ``dirs``; return the incomplete rest."""
    *records, rest = buffer.split(b"\0")
    for record in records:
        path = os.fsdecode(record[1:])
        if record[:1] == b"+" and os.path.isabs(path):
            dirs.add(path)
        elif record[:1] == b"-":
            dirs.discard(path)
    return b"" if len(rest) > MAX_RECORD else rest


def _pidfd(pid: int) -> int:
    try:
        return os.pidfd_open(pid)
    except (OSError, AttributeError):
        return -1


def reap(agent_pid: int, stdin: int = 0) -> int:
    """Watch ``agent_pid`` (our parent) and the records on ``stdin``; remove the dirs once it is gone."""
    dirs: set[str] = set()
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
    for path in dirs:
        shutil.rmtree(path, ignore_errors=True)
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
