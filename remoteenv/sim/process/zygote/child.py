"""What a forked child does to become the sim ``python <scene script> <arguments>`` would start.

Runs in the child of a zygote, right after the fork, before any scene code.
The child already has a fresh pid; this gives it the rest of a fresh start:
its own session and process group (as the launcher's ``start_new_session``),
the launcher's stdout and the sim's log as stderr, the launcher's pipe (its
descriptor appended to the arguments as ``--pipe-fd``), the agent's working
directory, ``sys.argv``, the scene's folder first on ``sys.path``, a numpy
global RNG seeded afresh (Python's ``random`` reseeds itself at a fork), and
then the script, run as ``__main__``. Its exit (a return, ``sys.exit``, an
uncaught exception) is the interpreter's, as for the script run by ``python``.
"""

from __future__ import annotations

import importlib
import io
import os
import runpy
import sys
from collections.abc import Sequence

from remoteenv.wire.messages.zygote_channel import ForkRequest


def become_sim(request: ForkRequest, fds: Sequence[int]) -> list[str]:
    """Set up this process as the sim of ``request`` (``fds``: stdout, stderr
    and the pipe, received with it) and return the scene's ``argv``. The
    zygote's own descriptors must be closed already."""
    os.setsid()
    stdout, stderr = fds[0], fds[1]
    os.dup2(stdout, 1)
    os.dup2(stderr, 2)
    for fd in (stdout, stderr):
        if fd > 2:
            os.close(fd)
    if isinstance(sys.stdout, io.TextIOWrapper):
        sys.stdout.reconfigure(line_buffering=os.isatty(1))  # as the interpreter sets it up at start
    argv = list(request.argv)
    if request.pipe:
        os.set_inheritable(fds[2], True)
        argv += ["--pipe-fd", str(fds[2])]
    os.chdir(request.cwd)
    if "numpy.random" in sys.modules:
        sys.modules["numpy.random"].seed()  # the legacy global RNG: a fresh interpreter seeds it from the OS
    return argv


def run_script(argv: list[str]) -> None:
    """Run the script ``argv[0]`` as ``__main__`` with ``sys.argv = argv`` and
    its folder first on ``sys.path``, as ``python`` does."""
    sys.argv = argv
    sys.path.insert(0, os.path.dirname(os.path.realpath(argv[0])))
    importlib.invalidate_caches()
    runpy.run_path(argv[0], run_name="__main__")


__all__ = ["become_sim", "run_script"]
