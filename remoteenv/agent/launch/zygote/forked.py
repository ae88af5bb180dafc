"""The handle of a sim a zygote forked: what :class:`subprocess.Popen` offers the launcher.

Runs in the agent process. The sim is the zygote's child, not ours, so its
exit status comes from the zygote, down the sim's own status channel (see
:mod:`remoteenv.wire.messages.zygote_channel`); a pidfd of the sim says whether it
still runs should the zygote be gone before it could report.
"""

from __future__ import annotations

import select
import socket
import subprocess
import threading
import time
import weakref

from remoteenv.wire.messages.zygote_channel import close_fds, int_field, receive_message
from remoteenv.wire.wire_errors import ProtocolError

#: The exit status given to a sim whose zygote died before it could report the real one.
LOST_STATUS = 1


class ForkedProcess:
    """A running (or finished) sim forked by the zygote ``zygote_pid``.

    Offers what the launcher uses of :class:`subprocess.Popen`: :attr:`pid`,
    :attr:`returncode`, :meth:`poll` and :meth:`wait`. Owns ``status`` (the
    child's status channel) and ``pidfd``; both are closed once the exit is known.
    """

    def __init__(self, pid: int, status: socket.socket, pidfd: int, zygote_pid: int) -> None:
        if pid < 2:
            raise ValueError(f"a forked sim's pid must be above 1, got {pid}")
        self.pid = pid
        self.zygote_pid = zygote_pid
        self.returncode: int | None = None
        #: Why :attr:`returncode` is not the process's own, or None.
        self.exit_note: str | None = None
        self._status: socket.socket | None = status
        self._pidfd = pidfd
        self._zygote_gone = False
        self._lock = threading.Lock()
        self._finalizer = weakref.finalize(self, _close, status, pidfd)

    def poll(self) -> int | None:
        """The exit status if the process has exited (and been reaped), else None."""
        with self._lock:
            return self._poll()

    def wait(self, timeout: float | None = None) -> int:
        """Wait for the exit and return its status; ``subprocess.TimeoutExpired`` after ``timeout`` seconds."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            with self._lock:
                code = self._poll()
                fd = self._pidfd if self._zygote_gone else (self._status.fileno() if self._status else -1)
            if code is not None:
                return code
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise subprocess.TimeoutExpired(f"sim pid {self.pid}", timeout or 0.0)
            poller = select.poll()
            poller.register(fd, select.POLLIN)
            poller.poll(None if left is None else max(1, int(left * 1000)))

    def _poll(self) -> int | None:
        if self.returncode is not None:
            return self.returncode
        if self._status is not None:
            try:
                got = receive_message(self._status, socket.MSG_DONTWAIT)
            except BlockingIOError:
                return None
            except (OSError, ProtocolError):
                got = None
            if got is not None:
                message, fds = got
                close_fds(fds)
                try:
                    self._finish(int_field(message, "exit", "returncode"))
                except ProtocolError:
                    self._finish(LOST_STATUS, f"its zygote (pid {self.zygote_pid}) reported no valid exit status")
                return self.returncode
            self._zygote_gone = True  # end of file: the zygote died first
        if _readable(self._pidfd):
            self._finish(LOST_STATUS, f"its exit status was lost with its zygote (pid {self.zygote_pid})")
        return self.returncode

    def _finish(self, returncode: int, note: str | None = None) -> None:
        self.returncode = returncode
        self.exit_note = note
        self._status = None
        self._finalizer()


def _readable(fd: int) -> bool:
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    return bool(poller.poll(0))


def _close(status: socket.socket, pidfd: int) -> None:
    status.close()
    close_fds([pidfd])


__all__ = ["LOST_STATUS", "ForkedProcess"]
