"""remoteenv: a MuJoCo simulation in its own process, driven as a Gymnasium env.

Agent-side API: :class:`OpenAIRemoteEnv`, :class:`RemoteVectorEnv`, :class:`Launcher`,
:class:`RemoteEnvError`. Sim-side API lives in :mod:`remoteenv.sim`. Importing
this package registers the shipped scenes: ``remoteenv/CartPole-v0`` and
``remoteenv/Reacher-v0``.
"""

from remoteenv.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.launcher import Launcher
from remoteenv.protocol import PROTOCOL_VERSION
from remoteenv.remote_env import OpenAIRemoteEnv
from remoteenv.vector_env import RemoteVectorEnv

from remoteenv._source_scenes import ensure_scenes_package

ensure_scenes_package()
import remoteenv.scenes.cartpole  # noqa: E402,F401  (registers the id)
import remoteenv.scenes.reacher  # noqa: E402,F401

__version__ = "0.1.0"

#: Gymnasium id of each shipped scene, by scene name.
SHIPPED_SCENES = {
    "cartpole": remoteenv.scenes.cartpole.ENV_ID,
    "reacher": remoteenv.scenes.reacher.ENV_ID,
}

__all__ = [
    "Launcher",
    "OpenAIRemoteEnv",
    "PROTOCOL_VERSION",
    "RemoteEnvError",
    "RemoteEnvTimeout",
    "RemoteVectorEnv",
    "SHIPPED_SCENES",
    "scene_path",
]


def scene_path(name: str) -> str:
    """Path of a shipped scene script: ``scene_path("cartpole")``."""
    import os

    import remoteenv.scenes as scenes

    path = os.path.join(os.path.dirname(scenes.__file__), name, f"{name}_scene.py")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no shipped scene named {name!r} (looked for {path})")
    return path
