"""What a sim process does when the agent that launched it dies.

Runs in the sim process. The server's loop checks the parent every
:data:`CHECK_INTERVAL_S` between requests (``RemoteControlledAgent.check_parent``),
the frame publisher as often while it waits; :class:`ParentWatch`
is the backstop for a sim whose main thread is busy (a long step, a stuck
scene): a daemon thread that notices the parent is gone and, if the main
thread has not shut down within a grace period, removes this instance's files
and ends the process. Either way an orphaned sim removes its files from the
launcher's private dir, and the last one to leave removes the dir itself
(nobody else will: the launcher that made it is dead).
"""

from __future__ import annotations

import os
import threading

#: Seconds between two looks at the parent pid (every sim-side loop and the watch).
CHECK_INTERVAL_S = 0.25
#: Seconds the main thread gets to shut down by itself once the parent is gone.
GRACE_S = 1.0


def parent_alive(parent_pid: int) -> bool:
    """True while ``parent_pid`` is still our parent (we are reparented when it dies)."""
    return os.getppid() == parent_pid


def remove_private_files(private_dir: str, instance: int) -> None:
    """Remove this instance's files (``sim-<instance>.*``) from the launcher's
    private dir, then the dir itself if nothing else is left in it."""
    prefix = f"sim-{instance}."
    try:
        names = os.listdir(private_dir)
    except OSError:
        return
    for name in names:
        if name.startswith(prefix):
            try:
                os.unlink(os.path.join(private_dir, name))
            except OSError:
                pass
    try:
        os.rmdir(private_dir)  # fails while another instance's files remain
    except OSError:
        pass


class ParentWatch:
    """Daemon thread that ends the process if ``parent_pid`` dies and the
    main thread does not finish shutting down within :data:`GRACE_S`.

    Args:
        parent_pid: the agent's pid.
        private_dir: the launcher's private dir, or None.
        instance: this sim's instance index (names its files).
    """

    def __init__(self, parent_pid: int, private_dir: str | None, instance: int) -> None:
        self.parent_pid = parent_pid
        self.private_dir = private_dir
        self.instance = instance
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
                    remove_private_files(self.private_dir, self.instance)
                os._exit(1)
