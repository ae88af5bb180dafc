"""Sim processes log to stderr by default, and leave a scene's own logging configuration alone."""

from __future__ import annotations

import os
import subprocess
import sys


def _sim_process(code: str) -> subprocess.CompletedProcess:
    """``code`` run in a fresh interpreter, as a sim process starts: no logging configured."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return subprocess.run(
        [sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=root), capture_output=True, text=True, timeout=60
    )


def test_by_default_records_go_to_stderr_with_the_instance() -> None:
    out = _sim_process(
        "import logging\n"
        "from remoteenv.sim.process.log import log_to_stderr\n"
        "log_to_stderr(3)\n"
        "logging.getLogger('remoteenv.sim.serving.sim_server').info('hello')\n"
    )
    assert out.stderr == "remoteenv sim 3: INFO hello\n"


def test_a_scene_that_configured_logging_keeps_its_own() -> None:
    out = _sim_process(
        "import logging, sys\n"
        "logging.basicConfig(stream=sys.stdout, level=logging.INFO, format='mine %(name)s %(message)s')\n"
        "from remoteenv.sim.process.log import log_to_stderr\n"
        "log_to_stderr(0)\n"
        "logging.getLogger('remoteenv.sim.serving.sim_server').info('routed')\n"
    )
    assert "mine remoteenv.sim.serving.sim_server routed" in out.stdout.splitlines() and out.stderr == ""
