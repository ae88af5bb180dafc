"""Sim-side diagnostics go through :mod:`logging`, under the ``remoteenv.sim`` logger.

Runs in the sim process. Its modules log with ``logging.getLogger(__name__)``
(``remoteenv.sim.process.pacing_levers``, ``remoteenv.sim.serving.sim_server``, ...). A sim
process's stderr is its log file, which the launcher keeps and quotes when
a sim fails to start; :func:`log_to_stderr` sends the records there, once,
unless the scene script configured logging itself. To route them elsewhere,
configure logging at the top of the scene script (it runs before
``run_scene``), e.g. ``logging.getLogger("remoteenv.sim").addHandler(...)``
or ``logging.basicConfig(...)``.
"""

from __future__ import annotations

import logging
import sys

LOGGER = "remoteenv.sim"


def log_to_stderr(instance: int) -> None:
    """Write ``remoteenv.sim`` records of level INFO and up to stderr, prefixed
    with the sim instance, unless logging is configured (a handler on the root
    or ``remoteenv.sim`` logger)."""
    logger = logging.getLogger(LOGGER)
    if logger.handlers or logging.getLogger().handlers:
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(f"remoteenv sim {instance}: %(levelname)s %(message)s"))
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)


__all__ = ["LOGGER", "log_to_stderr"]
