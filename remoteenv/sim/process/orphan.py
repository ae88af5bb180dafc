"""What a sim process does when the agent that launched it dies.

Runs in the sim process. The agent is the sim's parent, or for a sim a
zygote forked the zygote's parent, watched through the zygote's pidfd of it
(:func:`adopt_agent_pidfd`). First line: the orphan guard
(:mod:`remoteenv.sim.process.orphan_guard`, :func:`start_guard`), a tiny separate
process that ends the sim within a second of the agent's death whatever the
sim is doing (SIGTERM, then SIGKILL after 0.5 s) and removes its files.
Besides, the server's loop checks the parent every
:data:`CHECK_INTERVAL_S` between requests (``RemoteControlledAgent.check_parent``),
the frame publisher as often while it waits; :class:`ParentWatch`
is the backstop for a sim whose main thread is busy (a long step, a stuck
scene): a daemon thread that notices the parent is gone and, if the main
thread has not shut down within a grace period, removes this instance's files
and ends the process. Either way an orphaned sim removes its files from the
launcher's private dir, and the last one to leave removes the dir itself
(nobody else will: the launcher that made it is dead). Only the dir the
launcher made is touched: its identity is taken when the sim starts
(:func:`~remoteenv.wire.files.owned_dirs.identity`; a symlink or anything
not a dir of this user there means no tidying at all), and every removal goes
through its descriptor (:mod:`remoteenv.wire.files.owned_dirs`).
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import threading
import time

from remoteenv.sim.process import orphan_guard
from remoteenv.wire.files.owned_dirs import DirId, format_id, identity

#: Seconds between two looks at the parent pid (every sim-side loop and the watch).
CHECK_INTERVAL_S = 0.25
#: Seconds the main thread gets to shut down by itself once the parent is gone.
GRACE_S = 1.0


#: ``{agent pid: pidfd}`` of an agent that is not our parent: a sim forked by a
#: zygote (:mod:`remoteenv.sim.process.zygote`) watches the launching agent through the
#: zygote's pidfd of it, which it inherits.
_agent_pidfds: dict[int, int] = {}


def adopt_agent_pidfd(agent_pid: int, pidfd: int) -> None:
    """Watch ``agent_pid`` through ``pidfd`` (opened while it was known to be
    alive) instead of as our parent: it launched us through a zygote."""
    _agent_pidfds[agent_pid] = pidfd


def parent_alive(parent_pid: int) -> bool:
    """True while the agent ``parent_pid`` lives: while it is still our parent
    (we are reparented when it dies), or for a forked sim while its pidfd says so."""
    pidfd = _agent_pidfds.get(parent_pid)
    if pidfd is not None:
        poller = select.poll()
        poller.register(pidfd, select.POLLIN)
        return not poller.poll(0)
    return os.getppid() == parent_pid


def parent_gone_within(parent_pid: int, wait_s: float) -> bool:
    """True if ``parent_pid`` stops being our parent within ``wait_s`` seconds."""
    deadline = time.monotonic() + wait_s
    while parent_alive(parent_pid):
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)
    return True


def remove_private_files(private_dir: str, dir_id: DirId | None, instance: int) -> None:
    """Remove this instance's files (``sim-<instance>.*``) from the launcher's
    private dir, then the dir itself if no other sim's files are left in it;
    nothing unless the dir at that path is still ``dir_id``."""
    orphan_guard.remove_instance_files(private_dir, dir_id, instance)


class Guard:
    """The running orphan guard of this sim; :meth:`release` when the sim stops on its own."""

    def __init__(self, proc: subprocess.Popen[bytes], alive_fd: int) -> None:
        self.proc = proc
        self._alive_fd = alive_fd

    def release(self) -> None:
        """Tell the guard the sim is shutting down by itself (it then exits)."""
        if self._alive_fd >= 0:
            os.close(self._alive_fd)
            self._alive_fd = -1


def start_guard(parent_pid: int, private_dir: str | None, instance: int, dir_id: DirId | None = None) -> Guard | None:
    """Start the orphan guard for this process (None where it cannot run:
    not Linux, or no pidfds; :class:`ParentWatch` remains). ``dir_id``: the
    identity of ``private_dir`` (None: it tidies nothing there)."""
    if not sys.platform.startswith("linux") or not hasattr(os, "pidfd_open"):
        return None
    read_end, write_end = os.pipe()  # both close-on-exec: only the guard gets the read end
    agent_fd = _agent_pidfds.get(parent_pid)
    # The launcher's SIGTERM to the sim's process group is not for the guard:
    # blocked while it is started, the signal stays blocked in the guard across
    # exec, so none can end it before its first line (the sim's own SIGTERM
    # waits until the mask is restored).
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    try:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-I",
                "-S",
                orphan_guard.__file__,
                str(parent_pid),
                str(os.getpid()),
                private_dir or "",
                format_id(dir_id),
                str(instance),
                *([] if agent_fd is None else [str(agent_fd)]),
            ],
            stdin=read_end,
            stdout=subprocess.DEVNULL,
            close_fds=True,
            pass_fds=() if agent_fd is None else (agent_fd,),
        )
    except OSError:
        os.close(write_end)
        return None
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        os.close(read_end)
    return Guard(proc, write_end)


class ParentWatch:
    """Daemon thread that ends the process if ``parent_pid`` dies and the
    main thread does not finish shutting down within :data:`GRACE_S`.

    Args:
        parent_pid: the agent's pid.
        private_dir: the launcher's private dir, or None.
        instance: this sim's instance index (names its files).
        dir_id: the identity of ``private_dir`` (None: nothing there is tidied).
    """

    def __init__(self, parent_pid: int, private_dir: str | None, instance: int, dir_id: DirId | None = None) -> None:
        self.parent_pid = parent_pid
        self.private_dir = private_dir
        self.instance = instance
        self.dir_id = dir_id
        self._finished = threading.Event()
        self._thread = threading.Thread(target=self._run, name="remoteenv-parent-watch", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def finished(self) -> None:
        """Tell the watch that the main thread has shut down cleanly."""
        self._finished.set()

    def _run(self) -> None:
        while not self._finished.wait(CHECK_INTERVAL_S):
            if not parent_alive(self.parent_pid):
                if self._finished.wait(GRACE_S):
                    return
                if self.private_dir:
                    remove_private_files(self.private_dir, self.dir_id, self.instance)
                os._exit(1)


class AgentWatch:
    """What a serving sim does about its agent ``parent_pid`` (None: nothing):
    the orphan guard and the :class:`ParentWatch` from construction, and at
    :meth:`finish` whether this instance's files go.

    Args:
        parent_pid: the agent's pid, or None.
        private_dir: the launcher's private dir, or None.
        instance: this sim's instance index (names its files).
    """

    def __init__(self, parent_pid: int | None, private_dir: str | None, instance: int) -> None:
        self.parent_pid = parent_pid
        self.private_dir = private_dir
        self.instance = instance
        #: The private dir the launcher made, as it is now (before anyone could swap it).
        self.dir_id = identity(private_dir) if private_dir else None
        self._guard: Guard | None = None
        self._watch: ParentWatch | None = None
        if parent_pid is not None:
            self._guard = start_guard(parent_pid, private_dir, instance, self.dir_id)
            self._watch = ParentWatch(parent_pid, private_dir, instance, self.dir_id)
            self._watch.start()

    def finish(self, *, orphaned: bool, pipe_ended: bool) -> None:
        """The server has shut down: remove this instance's files if the agent is
        gone (``orphaned``: the server found it gone), then stop the guard and watch.

        ``pipe_ended``: the local pipe ended, a moment before the kernel
        reparents us: wait up to 0.5 s for that before deciding."""
        wait_s = 0.5 if pipe_ended else 0.0
        gone = orphaned or (self.parent_pid is not None and parent_gone_within(self.parent_pid, wait_s))
        if self.private_dir and gone:
            remove_private_files(self.private_dir, self.dir_id, self.instance)
        if self._watch is not None:
            self._watch.finished()
        if self._guard is not None:
            self._guard.release()
