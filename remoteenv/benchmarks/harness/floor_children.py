"""The child processes of the floor contenders and the worlds each one steps.

Benchmarks only: what ``process-floor`` (:mod:`remoteenv.benchmarks.harness.process_floor`)
and ``waits-floor`` (:mod:`remoteenv.benchmarks.harness.waits_floor`) share.
The agent side starts each child with two pipes and an anonymous shared
mapping (:class:`FloorChildren`); a child's side builds its Reacher worlds
(:func:`start_worlds`) and ticks them into its region's blocks
(:func:`tick`), keeping Reacher's time limit with next-step autoreset.
"""

from __future__ import annotations

import mmap
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

#: Reacher's time limit (``remoteenv/Reacher-v0`` and Gymnasium's ``Reacher-v5``), in steps.
MAX_EPISODE_STEPS = 50
#: What an agent writes on a child's request pipe to make it exit.
QUIT = b"q"


class FloorChildren:
    """The children of one floor contender, our ends of their pipes and their
    mapped regions (each list in the order the children were started)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.procs: list[subprocess.Popen[bytes]] = []
        self.requests: list[int] = []
        self.replies: list[int] = []
        self.regions: list[mmap.mmap] = []

    def spawn(self, module: str, args: Sequence[int], region_bytes: int) -> mmap.mmap:
        """Start ``python -m module *args REQUEST_FD REPLY_FD REGION_FD`` with a
        fresh region of ``region_bytes``; returns our mapping of that region."""
        region_fd = os.memfd_create(f"remoteenv-{self.name}")
        os.ftruncate(region_fd, region_bytes)
        request_r, request_w = os.pipe()
        reply_r, reply_w = os.pipe()
        self.requests.append(request_w)  # ours: closed by stop(), even if the child never starts
        self.replies.append(reply_r)
        theirs = (request_r, reply_w, region_fd)
        try:
            self.procs.append(
                subprocess.Popen([sys.executable, "-m", module, *map(str, (*args, *theirs))], pass_fds=theirs)
            )
            region = mmap.mmap(region_fd, region_bytes)
        finally:
            for fd in theirs:
                os.close(fd)
        self.regions.append(region)
        return region

    def read_ready(self, done: bytes) -> None:
        """Wait for each child's first ``done`` byte (its worlds built and reset)."""
        for fd in self.replies:
            self.read_done(fd, done)

    def read_done(self, fd: int, done: bytes) -> None:
        """Read one ``done`` byte from a child's reply pipe ``fd``; anything else (its end of file) is an error."""
        if os.read(fd, 1) != done:
            raise RuntimeError(f"a {self.name} child ended; its error is above")

    def stop(self) -> None:
        """Ask every child to exit, wait for it (killed after 30 s), close our
        pipes and unmap the regions (drop every view of them first)."""
        for fd in self.requests:
            try:
                os.write(fd, QUIT)
            except OSError:
                pass
            os.close(fd)
        for fd in self.replies:
            os.close(fd)
        self.requests, self.replies = [], []
        for proc in self.procs:
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.procs = []
        for region in self.regions:
            region.close()
        self.regions = []


def start_worlds(k: int, seed: int, threads: int | None = None) -> tuple[list[Any], Any, np.ndarray]:
    """A child's K Reacher worlds reset with seeds ``seed..seed+K-1``, stepped
    by the scene's own batched commands on ``threads`` physics threads (None:
    the sims' default): ``(envs, commands, first observations)``."""
    from remoteenv.benchmarks.harness.step_profile import reacher_class
    from remoteenv.sim.stepping.batch_commands import BatchCommands
    from remoteenv.sim.stepping.lock_step import LockStepping

    reacher = reacher_class()
    envs = [reacher() for _ in range(k)]
    commands = BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0, threads=threads)
    first = commands.reset_batch({"worlds": list(range(k)), "seeds": list(range(seed, seed + k))}, None, None)
    assert commands.stepper is not None
    return envs, commands, np.asarray(first["obs"])


def close_worlds(envs: list[Any], commands: Any) -> None:
    """Stop a child's physics threads and close its worlds."""
    commands.close()
    for env in envs:
        env.close()


def tick(
    commands: Any,
    views: dict[str, np.ndarray],
    worlds: list[int],
    elapsed: int,
    after_physics: Callable[[], None] | None = None,
) -> int:
    """One tick of every world of a child, results into its region's blocks:
    a step with the actions there, or, on the tick after the time limit, a
    reset of every world (Reacher never terminates, so a child's worlds end
    their episodes together). ``worlds``: ``0 .. K-1``; ``elapsed``: steps of
    the current episodes; returns the new count. ``after_physics`` as for the
    stepper's step."""
    if elapsed == MAX_EPISODE_STEPS:
        views["obs"][:] = np.asarray(commands.reset_batch({"worlds": worlds}, None, None)["obs"])
        views["reward"][:] = 0.0
        views["terminated"][:] = False
        elapsed = 0
    else:
        result = commands.stepper.step(worlds, views["actions"].copy(), None, after_physics)
        views["obs"][:] = result.obs
        views["reward"][:] = result.reward
        views["terminated"][:] = result.terminated
        elapsed += 1
    views["truncated"][:] = elapsed == MAX_EPISODE_STEPS
    return elapsed


__all__ = ["MAX_EPISODE_STEPS", "QUIT", "FloorChildren", "close_worlds", "start_worlds", "tick"]
