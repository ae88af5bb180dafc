"""One zygote process this agent started: its start, its fork requests, its end.

Runs in the agent process. The zygote (:mod:`remoteenv.sim.process.zygote`) is
started as ``python <remoteenv>/sim/process/zygote/start.py`` by path, so this
module never imports the sim side. It is our child, in a session of its
own; it exits when we close its control channel or when this process ends.
"""

from __future__ import annotations

import os
import select
import socket
import subprocess
import sys
import threading
import time
import weakref
from collections.abc import Mapping, Sequence
from pathlib import Path

from remoteenv.agent.launch.zygote.forked import ForkedProcess
from remoteenv.wire.messages.zygote_channel import (
    ForkRequest,
    channel_pair,
    close_fds,
    int_field,
    receive_message,
    send_message,
)
from remoteenv.wire.wire_errors import ProtocolError

#: The zygote's script, found by path (the agent side imports nothing of the sim side).
START_SCRIPT = str(Path(__file__).resolve().parents[3] / "sim" / "process" / "zygote" / "start.py")


class ZygoteUnavailable(Exception):
    """The zygote cannot fork this sim: start it the plain way.

    ``refused`` is True when the zygote declined this one request (it stays
    usable), False when it is gone or broken (it has been closed)."""

    def __init__(self, message: str, refused: bool = False) -> None:
        super().__init__(message)
        self.refused = refused


class Zygote:
    """A zygote for sims that run with ``env`` (the whole environment of the
    sim processes), preloading ``scenes``' imports. Starting returns at once;
    :meth:`fork` waits for the zygote's imports the first time.

    Raises ``OSError`` if the process cannot be started."""

    def __init__(self, env: Mapping[str, str], scenes: Sequence[str] = ()) -> None:
        ours, theirs = channel_pair()
        cmd = [sys.executable, START_SCRIPT, "--agent-pid", str(os.getpid()), "--control-fd", str(theirs.fileno())]
        for scene in scenes:
            cmd += ["--scene", scene]
        try:
            self.proc = subprocess.Popen(
                cmd,
                # Its sims get our stdout with each fork request; the zygote
                # itself holds none (a pipe reading our stdout ends with us).
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env=dict(env),
                pass_fds=(theirs.fileno(),),
                start_new_session=True,
            )
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
        self._control: socket.socket | None = ours
        self._lock = threading.Lock()
        self._ready = False
        #: Modules the zygote could not import (known once it is ready).
        self.failed: list[str] = []
        #: The sims it forked for us that may still run.
        self.children: weakref.WeakSet[ForkedProcess] = weakref.WeakSet()
        #: ``time.monotonic()`` of the last fork request or of the start.
        self.last_used = time.monotonic()
        self._finalizer = weakref.finalize(self, _stop, self.proc, ours)
        # Not at interpreter exit: the launchers stop their sims then, and the
        # zygote follows this process out by itself (end of file, pidfd).
        self._finalizer.atexit = False

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def ready(self) -> bool:
        """True once the zygote has said it finished its imports."""
        return self._ready

    @property
    def alive(self) -> bool:
        return self._control is not None and self.proc.poll() is None

    def busy(self) -> bool:
        """True while a sim it forked for us may still run."""
        return any(child.poll() is None for child in list(self.children))

    def fork(self, request: ForkRequest, fds: Sequence[int], timeout: float) -> ForkedProcess:
        """Fork a sim for ``request`` with ``fds`` (stdout, stderr and, with a
        pipe, the pipe: we keep ours). Waits up to ``timeout`` seconds in all.

        Raises :class:`ZygoteUnavailable` (the zygote refused, is gone or did not
        answer in time; the zygote is closed unless it refused)."""
        deadline = time.monotonic() + timeout
        with self._lock:
            if self._control is None:
                raise ZygoteUnavailable("the zygote is closed")
            try:
                if not self._ready:
                    self._wait_ready(deadline)
                self.last_used = time.monotonic()
                send_message(self._control, request.to_message(), list(fds))
                message, got = self._receive(deadline)
            except (OSError, ProtocolError, ZygoteUnavailable) as exc:
                self._close_locked()
                raise ZygoteUnavailable(f"zygote pid {self.pid}: {exc}") from None
        if message.get("kind") == "refused":
            close_fds(got)
            raise ZygoteUnavailable(f"zygote pid {self.pid} refused: {message.get('reason')}", refused=True)
        try:
            pid = int_field(message, "forked", "pid")
            if pid < 2:  # the launcher signals the group ``pid``: killpg(1) would signal every process
                raise ProtocolError(f"a forked reply named pid {pid}, which no child can have")
            if len(got) != 2:
                raise ProtocolError(f"a forked reply came with {len(got)} descriptors, expected 2")
            if pidfd_pid(got[1]) not in (pid, None):  # we signal that pid's group: it must be the child's
                raise ProtocolError(f"a forked reply named pid {pid}, but its pidfd is not that process's")
        except ProtocolError as exc:
            close_fds(got)
            self.close()
            raise ZygoteUnavailable(f"zygote pid {self.pid}: {exc}") from None
        child = ForkedProcess(pid, socket.socket(fileno=got[0]), got[1], self.pid)
        self.children.add(child)
        return child

    def close(self) -> None:
        """Close the control channel (the zygote exits) and reap the zygote."""
        with self._lock:
            self._close_locked()

    def abandon(self) -> None:
        """In a process forked from ours: forget this zygote (it is our parent's)
        without waiting for it; only our copy of its channel is closed."""
        self._finalizer.detach()
        control, self._control = self._control, None
        if control is not None:
            control.close()

    # ------------------------------------------------------------ internals

    def _close_locked(self) -> None:
        self._control = None
        self._finalizer()

    def _wait_ready(self, deadline: float) -> None:
        message, fds = self._receive(deadline)
        close_fds(fds)
        int_field(message, "ready", "pid")
        failed = message.get("failed")
        self.failed = [str(name) for name in failed] if isinstance(failed, list) else []
        self._ready = True

    def _receive(self, deadline: float) -> tuple[dict, list[int]]:
        assert self._control is not None
        poller = select.poll()
        poller.register(self._control, select.POLLIN)
        left = deadline - time.monotonic()
        if left <= 0 or not poller.poll(max(1, int(left * 1000))):
            raise ZygoteUnavailable("no answer in time")
        got = receive_message(self._control)
        if got is None:
            raise ZygoteUnavailable(f"it exited ({self.proc.poll()})")
        return got


def pidfd_pid(fd: int) -> int | None:
    """The pid of the process the pidfd ``fd`` refers to (from ``/proc/self/fdinfo``);
    None if the kernel does not say (or ``fd`` is no pidfd)."""
    try:
        with open(f"/proc/self/fdinfo/{fd}", "rb") as f:
            info = f.read(4096)
    except OSError:
        return None
    for line in info.splitlines():
        if line.startswith(b"Pid:"):
            try:
                return int(line[4:])
            except ValueError:
                return None
    return None


def _stop(proc: subprocess.Popen[bytes], control: socket.socket) -> None:
    """Close the channel and reap the zygote (it exits at the end of file; SIGKILL if not within 2 s)."""
    control.close()
    try:
        proc.wait(timeout=2.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


__all__ = ["START_SCRIPT", "Zygote", "ZygoteUnavailable", "pidfd_pid"]
