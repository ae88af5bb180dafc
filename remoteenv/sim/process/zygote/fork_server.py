"""The zygote's loop: answer fork requests, reap the children, follow the agent.

Runs in the zygote process (see :mod:`remoteenv.sim.process.zygote`). One thread,
one ``poll`` over the control channel, a pidfd of the agent and a pidfd of
each live child. A fork request is answered with the child's pid, a pidfd of
it and the launcher's end of the child's status channel, or refused with a
reason; when a child exits, its exit status goes down its status channel.
The loop returns None when the agent is gone or closed the channel (the
zygote then exits) and, in a forked child, the request that child serves.
"""

from __future__ import annotations

import argparse
import gc
import os
import resource
import select
import signal
import socket
import sys
import threading
from dataclasses import dataclass
from typing import Protocol

from remoteenv.sim.process.orphan import adopt_agent_pidfd
from remoteenv.sim.process.zygote.child import become_sim, run_script
from remoteenv.sim.process.zygote.preload import BASE_MODULES, installed, preload, scene_imports, shadowing
from remoteenv.sim.transport.limits import raise_fd_limit
from remoteenv.wire.messages.zygote_channel import (
    ForkRequest,
    channel_pair,
    close_fds,
    fork_request,
    receive_message,
    send_message,
)
from remoteenv.wire.wire_errors import ProtocolError, short_repr


@dataclass
class _Child:
    pid: int
    pidfd: int
    status: socket.socket


class ZygoteServer:
    """Serves fork requests on ``control`` for the agent ``agent_pid`` (our parent).

    Raises ``RuntimeError`` if ``agent_pid`` is not our parent any more (it
    died before we could watch it)."""

    def __init__(self, control: socket.socket, agent_pid: int, agent_pidfd: int | None = None) -> None:
        self.control = control
        if agent_pidfd is not None:
            self.agent_pidfd = agent_pidfd
        else:
            try:
                self.agent_pidfd = os.pidfd_open(agent_pid)
            except OSError:
                raise RuntimeError(f"the agent (pid {agent_pid}) is gone") from None
        if os.getppid() != agent_pid:  # checked after opening: the pidfd cannot name another process
            os.close(self.agent_pidfd)
            raise RuntimeError(f"the agent (pid {agent_pid}) is gone")
        self.children: dict[int, _Child] = {}  # by pidfd
        self.scenes: set[str] = set()

    def preload_scene(self, scene: str) -> list[str]:
        """Import what ``scene`` imports at its top from installed packages
        (once per scene, see :func:`~.preload.installed`); return what failed."""
        if scene in self.scenes:
            return []
        self.scenes.add(scene)
        failed = preload([name for name in scene_imports(scene) if installed(name)])
        _freeze_imports()
        return failed

    def serve(self) -> tuple[ForkRequest, list[int]] | None:
        """Serve until the agent is gone (None); in a forked child, return its request and descriptors."""
        _freeze_imports()
        poller = select.poll()
        poller.register(self.control, select.POLLIN)
        poller.register(self.agent_pidfd, select.POLLIN)
        watched: set[int] = set()
        while True:
            for fd, _events in poller.poll():
                if fd == self.agent_pidfd:
                    return None
                if fd in self.children:
                    poller.unregister(fd)
                    watched.discard(fd)
                    self._reap(self.children.pop(fd))
                    continue
                try:
                    got = receive_message(self.control)
                except ProtocolError as exc:
                    self._answer({"kind": "refused", "reason": str(exc)})
                    continue
                except OSError:
                    return None
                if got is None:
                    return None
                child = self._fork(*got)
                if child is not None:
                    return child
                for pidfd in self.children.keys() - watched:
                    poller.register(pidfd, select.POLLIN)
                    watched.add(pidfd)

    # ------------------------------------------------------------ internals

    def _fork(self, message: dict, fds: list[int]) -> tuple[ForkRequest, list[int]] | None:
        try:
            request = fork_request(message, fds)
        except ProtocolError as exc:
            close_fds(fds)
            self._answer({"kind": "refused", "reason": str(exc)})
            return None
        reason = self._refusal(request)
        if reason is not None:
            close_fds(fds)
            self._answer({"kind": "refused", "reason": reason})
            return None
        try:
            ours, theirs = channel_pair()
        except OSError as exc:  # out of descriptors, say: the launcher starts this one the plain way
            close_fds(fds)
            self._answer({"kind": "refused", "reason": f"no status channel: {exc}"})
            return None
        for stream in (sys.stdout, sys.stderr):  # nothing buffered here may be written again by the child
            if stream is not None:
                stream.flush()
        try:
            pid = os.fork()
        except OSError as exc:  # out of processes or memory: the launcher starts this one the plain way
            close_fds(fds)
            ours.close()
            theirs.close()
            self._answer({"kind": "refused", "reason": f"fork failed: {exc}"})
            return None
        if pid == 0:
            ours.close()
            theirs.close()
            self._close_in_child()
            return request, fds
        close_fds(fds)  # the child's now: a copy here would hide the pipe's end of file from the agent
        try:
            pidfd = os.pidfd_open(pid)
        except OSError as exc:
            os.kill(pid, signal.SIGKILL)  # unwatched, it must not serve: the launcher starts another
            os.waitpid(pid, 0)
            ours.close()
            theirs.close()
            self._answer({"kind": "refused", "reason": f"no pidfd of the child: {exc}"})
            return None
        self.children[pidfd] = _Child(pid, pidfd, ours)
        try:
            send_message(self.control, {"kind": "forked", "pid": pid}, [theirs.fileno(), pidfd])
        except OSError:
            pass  # the agent is gone: the loop notices
        finally:
            theirs.close()
        self.preload_scene(script_path(request))
        return None

    def _refusal(self, request: ForkRequest) -> str | None:
        threads = thread_count()
        if threads > 1:
            return f"the zygote runs {threads} Python threads (an imported module started them): forking is unsafe"
        shadowed = shadowing(os.path.dirname(script_path(request)))
        if shadowed:
            return f"files in the scene's folder shadow modules the zygote imported: {short_repr(shadowed)}"
        return None

    def _reap(self, child: _Child) -> None:
        try:
            _, status = os.waitpid(child.pid, 0)
            returncode = os.waitstatus_to_exitcode(status)
            send_message(child.status, {"kind": "exit", "returncode": returncode})
        except OSError:
            pass  # the launcher dropped the child's handle
        finally:
            child.status.close()
            os.close(child.pidfd)

    def _answer(self, message: dict) -> None:
        try:
            send_message(self.control, message)
        except OSError:
            pass

    def _close_in_child(self) -> None:
        """Drop the zygote's descriptors in a forked child (detached first, so
        that no socket object closes a number the sim reuses later), all but
        the agent's pidfd: the sim watches the agent through it."""
        os.close(self.control.detach())
        for child in self.children.values():
            os.close(child.status.detach())
            os.close(child.pidfd)
        self.children.clear()


def _freeze_imports() -> None:
    """Keep what the zygote imported out of the collector's view, here and in
    every child forked after: a child's collections (and the one its
    interpreter runs on the way out, ~60 ms of a sim's exit for the bundled
    scenes) would visit each of those objects, and touching them copies the
    zygote's pages into the child."""
    gc.freeze()


def script_path(request: ForkRequest) -> str:
    """The real path of the scene script of ``request`` (a relative one is
    relative to the sim's working directory, not the zygote's)."""
    return os.path.realpath(os.path.join(request.cwd, request.argv[0]))


def thread_count() -> int:
    """The Python threads of this process. Native thread pools are not
    counted: numpy's BLAS starts one at import, and the common ones stop and
    restart their threads around a fork themselves (``pthread_atfork``)."""
    return threading.active_count()


class AgentWatch(Protocol):
    """What :mod:`start` watches the agent with while the zygote imports."""

    #: A pidfd of the agent (the server keeps it).
    pidfd: int

    def stop(self) -> None: ...


def main(argv: list[str], watch: AgentWatch | None = None) -> int:
    """The zygote: preload, say ready, serve; in a forked child, run the scene script.

    ``watch`` (started by the script before any import) ends this process if
    the agent exits during the imports; the server takes over its pidfd of
    the agent and stops it before serving."""
    parser = argparse.ArgumentParser(description="remoteenv zygote (started by the launcher)")
    parser.add_argument("--agent-pid", type=int, required=True)
    parser.add_argument("--control-fd", type=int, required=True)
    parser.add_argument("--scene", action="append", default=[])
    args = parser.parse_args(argv)
    control = socket.socket(fileno=args.control_fd)
    inherited = resource.getrlimit(resource.RLIMIT_NOFILE)
    raise_fd_limit()  # two descriptors per live child
    failed = preload(BASE_MODULES)
    try:
        server = ZygoteServer(control, args.agent_pid, None if watch is None else watch.pidfd)
    except RuntimeError:
        return 0
    for scene in args.scene:
        failed += server.preload_scene(os.path.realpath(scene))
    if watch is not None:
        watch.stop()  # the server watches the agent from here on; it forks with no other thread
    try:
        send_message(control, {"kind": "ready", "pid": os.getpid(), "failed": failed})
    except OSError:
        return 0
    got = server.serve()
    if got is None:
        os._exit(0)  # nothing to tidy up: the sims watch the agent themselves
    request, fds = got
    resource.setrlimit(resource.RLIMIT_NOFILE, inherited)  # the sim's own, as a plain start gives it
    adopt_agent_pidfd(args.agent_pid, server.agent_pidfd)
    del server, control
    run_script(become_sim(request, fds))
    return 0


__all__ = ["ZygoteServer", "main", "script_path", "thread_count"]
