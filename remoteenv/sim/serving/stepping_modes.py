"""Which stepping strategy a sim server runs, and the commands only that mode answers.

Runs in the sim process.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.serving.commands import Handler, RegionHandler
from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.interfaces import Stepping
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.sim.stepping.plain_region_step import PlainRegionStep
from remoteenv.sim.stepping.real_time import Clock, RealTimeStepping
from remoteenv.wire.run_options.options import RunOptions


def stepping_and_commands(
    envs: Sequence[BaseEnv],
    instance: int,
    run: RunOptions,
    *,
    seed: int | None,
    clock: Clock,
) -> tuple[Stepping, dict[str, Handler], dict[str, Any], RegionHandler | None, PlainRegionStep | None]:
    """The stepping ``run`` asks for, the commands only that mode answers
    (``timing``, ``pause`` and ``resume`` in real time, ``reset_batch``,
    ``step_batch`` and ``shared_batch`` where the spaces allow in lock-step)
    and, in lock-step, how the worlds' physics steps (the handshake's
    ``physics_threads`` and ``stacked_hooks``, see :meth:`BatchCommands.physics`),
    and the handler of the requests found posted in the pipe's shared region
    (:meth:`BatchCommands.from_region`; None in real time) with, where the
    worlds step together, what serves the plain ones among them straight
    from the server's wait (:class:`~remoteenv.sim.stepping.plain_region_step.PlainRegionStep`;
    else None).
    ``seed`` is world 0's launch seed (world ``w``: ``seed + w``) for the delay
    and link streams; ``clock`` real time's (seconds, monotonic)."""
    if run.real_time:
        real = RealTimeStepping(envs, run, clock=clock, seed=seed)
        return real, {"timing": real.timing, "pause": real.pause, "resume": real.resume}, {}, None, None
    lock = LockStepping(envs, run, seed=seed)
    batch = BatchCommands(lock.worlds, envs[0].action_space, instance, threads=run.physics_threads)
    return lock, batch.handlers(), batch.physics(), batch.from_region, batch.plain_region
