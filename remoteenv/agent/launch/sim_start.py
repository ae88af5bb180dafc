"""Starting one sim process on this machine: forked by a zygote, or the plain way.

Runs in the agent process (used by :class:`remoteenv.agent.launch.launcher.Launcher`).
A sim is forked by this process's zygote for its environment
(:mod:`remoteenv.agent.launch.zygote`) when one can be used, and otherwise started
as ``python <scene script> ...`` in a session of its own. Either way its
stdin is ``/dev/null``, its stdout ours, its stderr its log file, its working
directory ours, and with a local pipe it gets the other end of a fresh
socketpair (``--pipe-fd``).
"""

from __future__ import annotations

import os
import socket
import subprocess
from dataclasses import dataclass

from remoteenv.agent.launch.sim_process import ProcessHandle
from remoteenv.agent.launch.zygote import registry as zygotes
from remoteenv.agent.launch.zygote.process import Zygote, ZygoteUnavailable
from remoteenv.wire.messages.zygote_channel import ForkRequest


@dataclass
class StartedSim:
    """A sim process just started (not ready yet)."""

    proc: ProcessHandle
    #: Where this process's stderr starts in its log.
    log_offset: int
    #: Our end of the local pipe, or None.
    pipe: socket.socket | None
    #: The zygote that forked it, or None if it was started the plain way.
    zygote_pid: int | None


def start_sim(
    cmd: list[str],
    *,
    env: dict[str, str],
    log_path: str,
    local_pipe: bool,
    use_zygote: bool,
    scene: str,
    timeout: float,
) -> StartedSim:
    """Start the sim ``cmd`` (``python``, the scene script, its arguments) with
    environment ``env``, appending its stderr to ``log_path``. ``use_zygote``
    allows a zygote; ``timeout`` bounds the wait for one (its first imports)."""
    zygote = zygotes.zygote_for(env, scene) if use_zygote else None
    ours = theirs = None
    if local_pipe:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        with open(log_path, "ab") as log:
            log_offset = log.tell()
            proc: ProcessHandle | None = None
            if zygote is not None:
                proc = _fork(zygote, cmd, log.fileno(), theirs, timeout, env)
            if proc is None:
                plain = cmd + ([] if theirs is None else ["--pipe-fd", str(theirs.fileno())])
                proc = subprocess.Popen(
                    plain,
                    stdin=subprocess.DEVNULL,
                    stderr=log,
                    env=env,
                    start_new_session=True,
                    pass_fds=() if theirs is None else (theirs.fileno(),),
                )
    except BaseException:
        if ours is not None:
            ours.close()
        raise
    finally:
        if theirs is not None:
            theirs.close()
    return StartedSim(proc, log_offset, ours, getattr(proc, "zygote_pid", None))


def _fork(
    zygote: Zygote, cmd: list[str], log_fd: int, pipe: socket.socket | None, timeout: float, env: dict[str, str]
) -> ProcessHandle | None:
    """Have ``zygote`` fork the sim ``cmd`` (stderr to ``log_fd``, the pipe's
    sim end ``pipe``); None if it cannot. A zygote that never got ready is not
    tried again for ``env``."""
    try:
        cwd = os.getcwd()
    except OSError:  # our working dir is gone: the plain start says what it makes of that
        return None
    try:
        os.fstat(1)
        stdout = 1
    except OSError:  # no stdout here: the sim gets /dev/null (a plain start would get none)
        stdout = os.open(os.devnull, os.O_WRONLY | os.O_CLOEXEC)
    fds = [stdout, log_fd] + ([] if pipe is None else [pipe.fileno()])
    try:
        return zygote.fork(ForkRequest(cmd[1:], cwd, pipe is not None), fds, timeout)
    except ZygoteUnavailable as exc:
        if not exc.refused and not zygote.ready:
            zygotes.failed(env)
        return None
    finally:
        if stdout != 1:
            os.close(stdout)


__all__ = ["StartedSim", "start_sim"]
