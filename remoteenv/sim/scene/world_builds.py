"""Building a sim process's worlds, refusing the rest when they would not fit in memory.

Runs in the sim process (:func:`remoteenv.sim.scene_main.run_scene`). The
worlds are built one by one. The second one's footprint (this process's
resident set grown by building it and rendering its cameras once, which
makes its renderers: a camera world's largest cost, ~42 MB under llvmpipe
against ~0.8 MB for a state world) is the figure each of the others is taken
to cost; if they do not fit in the memory this machine has available
(:mod:`remoteenv.wire.memory`), the sim refuses before building them, with
the figures and the fix on one line (:data:`~remoteenv.wire.wire_errors.RESOURCES_MARKER`),
instead of swapping or being killed halfway through a launch.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.wire.memory import resident_bytes, worlds_problem


class WorldsDoNotFit(MemoryError):
    """The worlds asked of this process would not fit in the memory available (one-line message)."""


def _touch_cameras(env: BaseEnv) -> None:
    rig = env.camera_rig
    if rig is not None:
        rig.pixels(env.data)  # makes the renderers now: part of what a world costs


def build_worlds(factory: Callable[[], BaseEnv], count: int, what: str) -> list[BaseEnv]:
    """``count`` worlds from ``factory``; raises :class:`WorldsDoNotFit` (having
    closed those built) when the ones after the second would not fit.
    ``what`` names this process in the message (e.g. "sim instance 0")."""
    envs: list[BaseEnv] = []
    try:
        for i in range(count):
            before = resident_bytes() if i == 1 else None
            envs.append(factory())
            if i <= 1:
                _touch_cameras(envs[-1])
            after = resident_bytes() if i == 1 else None
            if i == 1 and count > 2 and before is not None and after is not None:
                problem = worlds_problem(
                    count - 2,
                    max(after - before, 1),
                    f"{what} of {type(envs[0]).__name__}",
                    "ask for fewer worlds per process (envs_per_process) or in all (num_envs), or run "
                    "them on more machines; about {fit} more fit here",
                )
                if problem is not None:
                    raise WorldsDoNotFit(problem)
    except BaseException:
        for env in envs:
            _close_quietly(env)
        raise
    return envs


def _close_quietly(env: Any) -> None:
    try:
        env.close()
    except Exception:
        pass


__all__ = ["WorldsDoNotFit", "build_worlds"]
