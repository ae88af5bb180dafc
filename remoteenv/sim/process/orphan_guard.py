"""The orphan guard: a tiny process that ends a sim within a second of its agent's death.

Started by the sim (:func:`remoteenv.sim.process.orphan.start_guard`) as a script
(``python -I -S orphan_guard.py AGENT_PID SIM_PID PRIVATE_DIR DIR_ID INSTANCE [AGENT_PIDFD]``) that
imports only the standard library (and :mod:`remoteenv.wire.files.owned_dirs`,
loaded by path), with its stdin the read end of a pipe
whose write end only the sim holds: end of file there means the sim is gone.
It watches the agent through a pidfd (Linux 5.3+), which fires when the agent
*process* exits, whichever of its threads launched the sim: its own, or for a
sim that a zygote forked (whose parent is the zygote, not the agent) the
sim's, inherited as ``AGENT_PIDFD``.

When the agent dies, the guard sends the sim SIGTERM (the sim shuts down and
removes its files itself: the usual case), waits :data:`GRACE_S`, then sends
SIGKILL (a sim stuck in code that holds its interpreter lock cannot run its
own watch thread), and removes the sim's ``sim-<instance>.*`` files from the
private dir, and the dir once no other sim's files are left: only while the
dir at that path is the one the launcher made (``DIR_ID``, its ``dev:ino``
when the sim started), through its descriptor, never following a symlink
(:mod:`~remoteenv.wire.files.owned_dirs`). Being another
process, it needs nothing from the sim's interpreter. Where pidfds do not
exist it exits at once and the sim's own watch (:class:`ParentWatch`) is all
there is.

When the sim ends first (its launcher is stopping it, or it crashed; even
before the guard started) the guard stays until the agent dies, then tidies
up, or until the launcher SIGKILLs it with the sim's process group after
removing the dir (the sim starts it with SIGTERM blocked, and it ignores the
SIGTERM the launcher sends that group first): an agent killed while it
closed its env (a pool terminating its worker) leaves no dir behind.
"""

from __future__ import annotations

import os
import select
import signal
import sys
from types import ModuleType


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
#: Seconds the sim gets to shut down by itself after SIGTERM before SIGKILL.
GRACE_S = 0.5


def remove_instance_files(private_dir: str, dir_id: tuple[int, int] | None, instance: int) -> None:
    """Remove ``sim-<instance>.*`` from ``private_dir``; then, if no other sim's
    files are left, the dir with what remains (the dead launcher's own files).
    Nothing at all unless the dir there is ``dir_id`` (the one the launcher made;
    None: it was not a dir of ours when the sim started)."""
    if dir_id is not None:
        owned_dirs.remove_files(private_dir, dir_id, f"sim-{instance}.", "sim-")


def _readable(fd: int, timeout_s: float | None) -> bool:
    poller = select.poll()
    poller.register(fd, select.POLLIN | select.POLLHUP)
    return bool(poller.poll(None if timeout_s is None else timeout_s * 1000))


def guard(
    agent_pid: int,
    sim_pid: int,
    private_dir: str,
    instance: int,
    sim_gone_fd: int = 0,
    agent_fd: int = -1,
    dir_id: tuple[int, int] | None = None,
) -> int:
    """Watch ``agent_pid`` and the sim ``sim_pid`` (our parent; ``sim_gone_fd``
    reaches end of file when it exits). ``agent_fd`` is the sim's pidfd of the
    agent when the agent is not the sim's parent (else -1); ``dir_id`` the
    identity of ``private_dir`` (see :func:`remove_instance_files`). Returns the exit status."""
    if not hasattr(os, "pidfd_open"):
        return 0  # no pidfds here: the sim's own watch is the fallback
    agent = agent_fd if agent_fd >= 0 else _pidfd(agent_pid)
    # Reparented already: the sim ended before we started (its launcher may
    # have stopped it at once); its pid may be another process's now.
    sim = _pidfd(sim_pid) if os.getppid() == sim_pid else -1
    if agent_fd < 0 and agent >= 0 and sim >= 0 and not _sim_parent_is(sim_pid, agent_pid):
        os.close(agent)
        agent = -1  # the agent died before we could watch it
    if sim < 0 or (agent >= 0 and not _agent_ends_first(agent, sim_gone_fd)):
        # The sim ended first (e.g. its launcher is stopping it), so wait for
        # the launcher to finish: it removes the dir, then SIGKILLs this guard
        # with the sim's process group. If the launcher dies before that
        # (killed while it closed the env), tidy up for it.
        if agent >= 0:
            _readable(agent, None)
        if private_dir:
            remove_instance_files(private_dir, dir_id, instance)
        return 0
    _signal(sim, signal.SIGTERM)
    if not _readable(sim_gone_fd, GRACE_S):
        _signal(sim, signal.SIGKILL)
        _readable(sim_gone_fd, 1.0)
    if private_dir:
        remove_instance_files(private_dir, dir_id, instance)
    return 0


def _pidfd(pid: int) -> int:
    """A pidfd of ``pid``, or -1 if it is gone."""
    try:
        return os.pidfd_open(pid)
    except OSError:
        return -1


def _agent_ends_first(agent: int, sim_gone_fd: int) -> bool:
    """Wait until the agent or the sim ends; True if the agent did."""
    poller = select.poll()
    poller.register(sim_gone_fd, select.POLLIN | select.POLLHUP)
    poller.register(agent, select.POLLIN)
    return agent in {fd for fd, _ in poller.poll()}


def _signal(pidfd: int, sig: int) -> None:
    try:
        signal.pidfd_send_signal(pidfd, sig)
    except OSError:  # gone already
        pass


def _sim_parent_is(sim_pid: int, agent_pid: int) -> bool:
    try:
        with open(f"/proc/{sim_pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1]) == agent_pid
    except (OSError, IndexError, ValueError):
        return True  # cannot tell: the pidfd will


def main(argv: list[str]) -> int:
    agent_pid, sim_pid, private_dir, instance = int(argv[0]), int(argv[1]), argv[2], int(argv[4])
    dir_id = owned_dirs.parse_id(argv[3])
    agent_fd = int(argv[5]) if len(argv) > 5 else -1
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C in a terminal is for the agent
    # The launcher's SIGTERM to the sim's process group is for the sim: this
    # guard lives until the launcher has removed the dir (then SIGKILL). The
    # sim starts it with SIGTERM blocked, so this holds from its first line.
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return guard(agent_pid, sim_pid, private_dir, instance, agent_fd=agent_fd, dir_id=dir_id)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
