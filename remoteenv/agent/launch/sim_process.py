"""One sim process this machine launched: its handle, and stopping a group of them.

Runs in the agent process (used by :class:`remoteenv.agent.launch.launcher.Launcher`).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from typing import Protocol

from remoteenv.agent.launch.dir_reaper import forget_dir
from remoteenv.wire.files.file_reads import read_tail
from remoteenv.wire.files.owned_dirs import DirId, remove_dir

_STDERR_TAIL_LINES = 20


class ProcessHandle(Protocol):
    """What the launcher uses of a started process: a :class:`subprocess.Popen`
    (started the plain way) or a :class:`remoteenv.agent.launch.zygote.ForkedProcess`."""

    @property
    def pid(self) -> int: ...

    @property
    def returncode(self) -> int | None: ...

    def poll(self) -> int | None: ...

    def wait(self, timeout: float | None = None) -> int: ...


@dataclass
class SimProcess:
    """One launched sim process."""

    instance: int
    proc: ProcessHandle
    log_path: str
    ready_file: str
    endpoint: str | None = None
    restarts: int = 0
    #: The sim's public Z85 CURVE key when CURVE is on, else None.
    curve_server_key: bytes | None = None
    #: Where this process's stderr starts in the log (a restart appends to it).
    log_offset: int = 0
    #: The launcher's end of the local pipe (see :mod:`remoteenv.protocol`), or None.
    pipe: socket.socket | None = None
    #: The zygote that forked this process (its parent), or None if it was started the plain way.
    zygote_pid: int | None = None

    def close_pipe(self) -> None:
        if self.pipe is not None:
            self.pipe.close()
            self.pipe = None

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def node(self) -> None:
        """Where the process runs: always this machine."""
        return None

    def stderr_tail(self, lines: int = _STDERR_TAIL_LINES) -> str:
        """The last ``lines`` lines the process wrote to stderr."""
        try:
            text = read_tail(self.log_path, 16384, self.log_offset, what="sim log").decode("utf-8", "replace")
        except (OSError, ValueError):  # gone, or not a regular file any more (UnreadableFile)
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def death(self) -> str | None:
        """Why the process is gone (exit code or signal, stderr tail), or None if it runs."""
        code = self.proc.poll()
        if code is None:
            return None
        if code < 0:
            try:
                how = f"killed by signal {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exited with code {code}"
        note = getattr(self.proc, "exit_note", None)
        if note:
            how += f" ({note})"
        tail = self.stderr_tail()
        text = f"pid {self.proc.pid} {how}"
        if tail:
            text += f"; last lines of its stderr:\n{tail}"
        return text


def kill_group(pid: int, sig: int) -> None:
    """Send ``sig`` to the process group a sim leads (its pid), if it still exists.

    Refuses (``ValueError``) a pid below 2: ``killpg(1)`` is ``kill(-1)``,
    which signals every process we may signal, and ``killpg(0)`` our own group."""
    if pid < 2:
        raise ValueError(f"refusing to signal process group {pid}: not a sim's")
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


@dataclass
class LaunchState:
    """What a launcher's finalizer needs (its private dir and its sims); holds
    no reference to the launcher, so the launcher can be garbage collected."""

    workdir: str
    #: The identity of the dir made at ``workdir`` (None: not a dir of ours, nothing is removed).
    workdir_id: DirId | None = None
    sims: list[SimProcess] = field(default_factory=list)


def stop_all(state: LaunchState, grace: float = 2.0) -> None:
    """Stop every sim of ``state`` (SIGTERM to its process group, SIGKILL after
    ``grace`` seconds), remove the private dir, then SIGKILL what is left of
    each sim's process group and close the pipes.

    The order matters when this process is killed on the way (a pool
    terminating its worker while the env closes): until the dir is gone,
    each sim's orphan guard (:mod:`remoteenv.sim.process.orphan_guard`, in the sim's
    process group; it ignores the SIGTERM) still watches this process and
    removes the dir if it dies."""
    for sim in state.sims:
        if sim.proc.poll() is None:
            kill_group(sim.proc.pid, signal.SIGTERM)
    deadline = time.monotonic() + grace
    for sim in state.sims:
        try:
            sim.proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            kill_group(sim.proc.pid, signal.SIGKILL)
            sim.proc.wait()
    if state.workdir_id is not None:  # through descriptors: nothing planted there is followed or opened
        remove_dir(state.workdir, state.workdir_id)
    forget_dir(state.workdir)
    for sim in state.sims:
        # Reap the group even if the sim exited by itself but left children (its orphan guard).
        kill_group(sim.proc.pid, signal.SIGKILL)
        sim.close_pipe()


__all__ = ["LaunchState", "SimProcess", "kill_group", "stop_all"]
