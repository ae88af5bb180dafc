"""The zygote's script: ``python start.py --agent-pid P --control-fd F [--scene S ...]``.

Run by path (not ``-m``), so that no working directory is put on
``sys.path``; the folder of this file is taken off it at once: the zygote
finds modules as a scene script does, without the scene's folder (which a
forked sim puts first, see :mod:`remoteenv.sim.process.zygote.child`).

Its first instructions, before any import beyond the standard library's
smallest, watch the agent: a thread polls a pidfd of it and ends this
process the moment it exits, while the imports (seconds on a busy machine)
run. The server stops that thread before it serves (it forks only with no
other Python thread) and watches the pidfd itself from then on.
"""

import os
import select
import sys
import threading


class EarlyWatch:
    """Ends this process as soon as the agent ``agent_pid`` (our parent) exits, until :meth:`stop`."""

    def __init__(self, agent_pid: int) -> None:
        try:
            self.pidfd = os.pidfd_open(agent_pid)
        except (OSError, AttributeError):
            os._exit(0)  # gone already (or no pidfds: the launcher uses no zygote there)
        if os.getppid() != agent_pid:  # checked after opening: the pidfd cannot name another process
            os._exit(0)
        self._stop_r, self._stop_w = os.pipe()
        self._thread = threading.Thread(target=self._run, name="remoteenv-zygote-early-watch", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        poller = select.poll()
        poller.register(self.pidfd, select.POLLIN)
        poller.register(self._stop_r, select.POLLIN)
        if self.pidfd in {fd for fd, _ in poller.poll()}:
            os._exit(0)  # the agent is gone: nothing forked yet, nothing to tidy up

    def stop(self) -> None:
        """Stop watching (the thread ends); :attr:`pidfd` stays open for the server."""
        os.write(self._stop_w, b"x")
        self._thread.join()
        os.close(self._stop_r)
        os.close(self._stop_w)


def agent_pid_of(argv: list) -> int:
    """The value of ``--agent-pid`` in ``argv`` (0 if absent or not a number: the server's parser says so)."""
    for i, arg in enumerate(argv[:-1]):
        if arg == "--agent-pid":
            try:
                return int(argv[i + 1])
            except ValueError:
                return 0
    return 0


if __name__ == "__main__":
    del sys.path[0]
    _pid = agent_pid_of(sys.argv[1:])
    _watch = EarlyWatch(_pid) if _pid > 0 else None
    from remoteenv.sim.process.zygote.fork_server import main

    sys.exit(main(sys.argv[1:], _watch))
