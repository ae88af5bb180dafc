"""What every sim-side process does to start and stop the way its launcher expects.

Runs in the sim process (the sim server and the frame publisher alike):
SIGTERM ends the process through ``SystemExit`` (so ``finally`` blocks run
and the socket files go), the ready file tells the launcher where the
process listens, and an ipc socket file is removed on the way out.
"""

from __future__ import annotations

import json
import os
import signal
from typing import Any

from remoteenv.wire.addresses import ipc_path
from remoteenv.wire.files.safe_writes import write_atomic


def exit_on_sigterm() -> None:
    """Turn SIGTERM into ``SystemExit(128 + SIGTERM)`` (Python does so for SIGINT already)."""

    def _stop(signum: int, _frame: Any) -> None:
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, _stop)


def write_ready_file(path: str, endpoint: str, instance: int) -> None:
    """Write ``{"endpoint", "pid", "instance"}`` as JSON to ``path``, atomically
    (a reader sees no file or the whole of it)."""
    write_atomic(path, json.dumps({"endpoint": endpoint, "pid": os.getpid(), "instance": instance}))


def remove_ipc_file(endpoint: str) -> None:
    """Remove the socket file of an ipc endpoint, if it is one and still there."""
    path = ipc_path(endpoint)
    if path is not None:
        try:
            os.unlink(path)
        except OSError:
            pass


__all__ = ["exit_on_sigterm", "remove_ipc_file", "write_ready_file"]
