"""``remoteenv.prestart()``: get this process ready to launch sims fast, ahead of the first ``gym.make``.

Runs in the agent process. Each sim is forked by a zygote
(:mod:`remoteenv.agent.launch.zygote`), a process that has imported what sims need;
the first launch in a process starts that zygote and waits for its imports
(about as long as starting a sim the plain way). :func:`prestart` starts it
now, in the background, and imports the env classes here, so that a
``gym.make`` a moment later (after your own imports, say) finds both ready.
"""

from __future__ import annotations

import importlib

from remoteenv.agent.launch.sim_command import launch_environment
from remoteenv.agent.launch.zygote import registry


def prestart(env_id: str | None = None, render_mode: str | None = None) -> bool:
    """Start the zygote for sims launched from this process (returns at once)
    and import the env classes.

    Args:
        env_id: a registered remote env id (``"remoteenv/CartPole-v0"``,
            ``"my_arm/MyArm-v0"``): the zygote also imports what its scene
            script imports. None: only what every sim needs.
        render_mode: the render mode the envs will use (``"human"`` sims are
            never forked: nothing is started for it).

    Returns False, starting nothing, where zygotes are off (``REMOTEENV_ZYGOTE=0``,
    not Linux 5.3+) or with ``render_mode="human"``.
    """
    scene = None
    if env_id is not None:
        from remoteenv.registration import find_spec

        scene = find_spec(env_id).kwargs.get("scene")
    # The zygote first: it imports on another core while we import the env classes.
    started = render_mode != "human" and registry.prestart(launch_environment(render_mode), scene)
    importlib.import_module("remoteenv.remote_env")
    importlib.import_module("remoteenv.vector_env")
    return started


__all__ = ["prestart"]
