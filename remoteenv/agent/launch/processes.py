"""Whether a local process lives: the one liveness test of the agent side.

Runs in the agent process (launcher, attach, the torch streaming helpers).
"""

from __future__ import annotations

import os


def pid_alive(pid: int) -> bool:
    """True while process ``pid`` exists on this machine and is not a zombie.

    Reads ``/proc/<pid>/stat`` on Linux; where that cannot be read, asks with
    signal 0 (a process owned by someone else counts as alive).
    """
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False
    except (OSError, IndexError):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True


__all__ = ["pid_alive"]
