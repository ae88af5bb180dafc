"""A launch's private directory: where its sims' files and ipc sockets live.

Runs in the agent process. Each :class:`~remoteenv.agent.launch.launcher.Launcher`
makes one (mode 0700, ``remoteenv-XXXXXXXX``) for its sims' ready files,
logs, keys and, with the default ipc transport, their sockets
(``sim-<instance>.sock``). The OS caps a Unix socket's path
(``zmq.IPC_PATH_MAX_LEN``: 107 bytes on Linux, 103 on macOS), and a long
``TMPDIR`` (a batch system's per-job directory, a test's temporary dir)
can push a socket's path past it, so that the sim could not bind.
:func:`make_private_dir` therefore makes the directory in the system's
temporary directory when every socket's path fits there, else in the first
of ``$XDG_RUNTIME_DIR`` and ``/tmp`` where it fits (a directory only its
user can open either way), else raises before any sim starts, saying what
to set.
"""

from __future__ import annotations

import os
import tempfile

import zmq

from remoteenv.agent.errors import LaunchError

#: The prefix of every launch's private directory.
PREFIX = "remoteenv-"
#: Longest path of a Unix socket, in bytes (sun_path less its NUL).
MAX_SOCKET_PATH = int(getattr(zmq, "IPC_PATH_MAX_LEN", 0) or 103)
#: ``mkdtemp``'s random part of a directory name.
_RANDOM_CHARS = 8


def socket_path_length(base: str, num_instances: int) -> int:
    """Bytes of the longest socket path (``sim-<last instance>.sock``) of a
    private directory made in ``base``."""
    name = f"{PREFIX}{'x' * _RANDOM_CHARS}/sim-{max(0, num_instances - 1)}.sock"
    return len(os.fsencode(os.path.join(os.path.abspath(base), name)))


def _fallbacks() -> list[str]:
    runtime = os.environ.get("XDG_RUNTIME_DIR", "")
    return [d for d in (runtime, "/tmp") if d and os.path.isabs(d)]


def make_private_dir(num_instances: int, sockets: bool = True) -> str:
    """Make a launch's private directory and return its path.

    Args:
        num_instances: how many sims the launch starts (instances ``0 .. n - 1``).
        sockets: whether the sims bind ipc sockets in it (the default transport);
            without them it is made in the system's temporary directory as is.

    Raises:
        LaunchError: no candidate directory leaves room for the sockets' paths.
    """
    base = tempfile.gettempdir()
    if not sockets or socket_path_length(base, num_instances) <= MAX_SOCKET_PATH:
        return tempfile.mkdtemp(prefix=PREFIX, dir=base)
    for candidate in _fallbacks():
        if socket_path_length(candidate, num_instances) > MAX_SOCKET_PATH:
            continue
        if os.path.isdir(candidate) and os.access(candidate, os.W_OK | os.X_OK):
            return tempfile.mkdtemp(prefix=PREFIX, dir=candidate)
    need = socket_path_length(base, num_instances)
    raise LaunchError(
        f"the sims' ipc sockets would have paths of {need} bytes in the temporary directory {base[:200]!r}, "
        f"over the OS limit of {MAX_SOCKET_PATH}, and neither $XDG_RUNTIME_DIR nor /tmp can take them: "
        "set TMPDIR to a shorter directory, or pass transport='tcp'"
    )


__all__ = ["MAX_SOCKET_PATH", "PREFIX", "make_private_dir", "socket_path_length"]
