"""Starting a vector env's sims, and relaunching costly worlds over more processes.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from remoteenv.agent.launch.sim_group import SimGroup
from remoteenv.agent.session.sim_session import SimSession, open_session
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
) -> tuple[SimSession, int]:
    """Start (or take) the sims of ``num_envs`` worlds, ``envs_per_process`` (K,
    capped at ``num_envs``) each: the open session and the K it runs.

    ``launch``: :func:`~remoteenv.agent.session.sim_session.open_session`'s options.
    ``regroup`` (given for the default layout only): the worlds are placed
    again from what one costs (the handshake's ``world_cost_s``, see
    :func:`~remoteenv.agent.vector.vector_layout.default_envs_per_process`):
    if that gives another K, the sims are closed and relaunched once in a
    group from ``regroup()``.
    """
    per_process = min(envs_per_process, num_envs)
    session = open_session(group, label, scene, len(world_slices(num_envs, per_process)), per_process, **launch)
    if regroup is None:
        return session, per_process
    better = min(default_envs_per_process(num_envs, session.handshake.world_cost_s), num_envs)
    if better == per_process:
        return session, per_process
    session.close()
    session = open_session(regroup(), label, scene, len(world_slices(num_envs, better)), better, **launch)
    return session, better


__all__ = ["open_worlds"]
