"""Starting a vector env's sims, and relaunching costly worlds over more processes.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from remoteenv.agent.launch.sim_group import SimGroup
from remoteenv.agent.session.session import SimSession, open_session
from remoteenv.agent.vector.vector_layout import default_envs_per_process, world_slices


def open_worlds(
    group: SimGroup,
    label: str,
    scene: str,
    num_envs: int,
    envs_per_process: int,
    launch: dict[str, Any],
    *,
    regroup: Callable[[], SimGroup] | None = None,
) -> tuple[SimSession, int, float | None]:
    """Start (or take) the sims of ``num_envs`` worlds, ``envs_per_process`` (K,
    capped at ``num_envs``) each: the open session, the K it runs, and what one
    world's tick costs (seconds; None unless measured).

    ``launch``: :func:`~remoteenv.agent.session.session.open_session`'s options.
    ``regroup`` (given for the default layout only): the first sim measures
    what one world's whole tick costs (the handshake's ``world_cost_s``:
    physics and every hook, however the scene renders; see
    :mod:`remoteenv.sim.scene.world_cost`) and the worlds are placed again
    from it (:func:`~remoteenv.agent.vector.vector_layout.default_envs_per_process`):
    if that gives another K, the sims are closed and relaunched once in a
    group from ``regroup()``.
    """
    per_process = min(envs_per_process, num_envs)
    measure = regroup is not None
    slices = len(world_slices(num_envs, per_process))
    session = open_session(group, label, scene, slices, per_process, measure_world_cost=measure, **launch)
    cost = session.handshake.world_cost_s
    if regroup is None:
        return session, per_process, cost
    better = min(default_envs_per_process(num_envs, cost), num_envs)
    if better == per_process:
        return session, per_process, cost
    session.close()
    session = open_session(regroup(), label, scene, len(world_slices(num_envs, better)), better, **launch)
    return session, better, cost


__all__ = ["open_worlds"]
