"""The layout gate: a sim that measures one world before it builds the ones it serves.

Runs in the sim process, before any served world exists. When the agent's
default layout does not know a scene yet, and the scene says it steps its
worlds as one batch, the agent launches the layout such worlds get when they
are cheap (all of them in one process) with ``--layout-gate FILE``. The sim
then makes a scratch world as it would make a served one (never served, its
viewer off), measures its whole tick
(:func:`~remoteenv.sim.scene.world_cost.step_cost`; the world is closed
after), writes what the layout rule reads to ``FILE`` and waits for the
agent's word: SIGUSR1, go on and build the worlds (:class:`GoSignal`);
SIGTERM (the agent found another layout right, or closed), end before
building them. The served worlds
are built only after the measurement, as in any other launch, so nothing of
it reaches them (their RNGs, their episode counts). The format of ``FILE``
is in :mod:`remoteenv.wire.protocol` ("The layout gate").
"""

from __future__ import annotations

import json
import math
import os
import select
import signal
import sys
from collections.abc import Callable
from typing import Any

from remoteenv.sim.process.orphan import parent_alive
from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.world_cost import step_cost
from remoteenv.sim.stepping.batch_step import steps_as_one_batch
from remoteenv.wire.files.safe_writes import write_atomic
from remoteenv.wire.messages.handshake import worlds_that_fit

#: The agent's go: build the worlds and serve them.
GO_SIGNAL = signal.SIGUSR1
#: Seconds between two looks at whether the agent still lives, while waiting.
_LOOK_S = 0.1


def _caught(signum: int, frame: Any) -> None:
    """The go, taken by the Python handler; the wakeup fd carries it to the wait."""


class GoSignal:
    """The agent's go, caught from when this is made until :meth:`wait` returns.

    Made before anything the agent could answer (a go that came first would end
    the process: SIGUSR1's default). A handler, not a blocked signal: a sim
    started the plain way already has threads (OpenBLAS's, from numpy's
    import), and a process-directed signal goes to any thread that does not
    block it; a handler runs whichever thread takes it, and Python's wakeup fd
    carries the signal's number to the main thread's wait."""

    def __init__(self) -> None:
        self._read, write = os.pipe()
        os.set_blocking(write, False)
        self._write = write
        self._previous_fd = signal.set_wakeup_fd(write)
        self._previous = signal.signal(GO_SIGNAL, _caught)

    def wait(self, parent_pid: int | None) -> None:
        """Return once the go came; exit if the agent ``parent_pid`` dies first."""
        try:
            while True:
                ready, _, _ = select.select([self._read], [], [], _LOOK_S)
                if ready and GO_SIGNAL in os.read(self._read, 64):
                    return
                if parent_pid is not None and not parent_alive(parent_pid):
                    sys.exit(0)  # the agent is gone: nothing was built, its dir goes with it
        finally:
            if signal.getsignal(GO_SIGNAL) is _caught:  # a scene that set its own meanwhile keeps it
                signal.signal(GO_SIGNAL, self._previous)
            signal.set_wakeup_fd(self._previous_fd)
            os.close(self._read)
            os.close(self._write)


def facts_of(world: BaseEnv, cost_s: float) -> dict[str, Any]:
    """What the layout rule reads of a scene's worlds, from one of them that
    cost ``cost_s`` seconds a tick: that cost (None if not finite), whether its
    worlds step as one batch (its class's stacked hooks, stepped in one
    ``mujoco.batch``) and how many worlds' observations one batch reply carries."""
    return {
        "world_cost_s": cost_s if math.isfinite(cost_s) else None,
        "stacked_hooks": steps_as_one_batch([world]),
        "worlds_that_fit": worlds_that_fit(world.observation_space),
        "pid": os.getpid(),
    }


def report_and_wait(path: str, make_world: Callable[[], BaseEnv], parent_pid: int | None, go: GoSignal) -> None:
    """Measure a world from ``make_world``, write :func:`facts_of` it to ``path``
    (atomically) and return once the agent says go (``go``, made before); exit
    if the agent dies first."""
    world = make_world()
    facts = facts_of(world, step_cost(lambda: world))
    write_atomic(path, json.dumps(facts, allow_nan=False))
    go.wait(parent_pid)


__all__ = ["GO_SIGNAL", "GoSignal", "facts_of", "report_and_wait"]
