"""remoteenv: a MuJoCo simulation in its own process, driven as a Gymnasium env.

Agent-side API: :class:`OpenAIRemoteEnv`, :class:`RemoteVectorEnv`, :class:`Launcher`,
:class:`RemoteEnvError` and its subclasses, :func:`prestart`. Sim-side API lives in
:mod:`remoteenv.sim`; the wire format in :mod:`remoteenv.wire`. Importing this
package registers the shipped scenes (``remoteenv/CartPole-v0``,
``remoteenv/Reacher-v0``, ``remoteenv/Hexapod-v0``) and nothing else: the agent-side classes are loaded
on first use, so a sim process (which imports :mod:`remoteenv.sim`) never
loads agent code.

The tree says which process a module runs in:

- ``remoteenv/wire/``: both (spec, codec, framing, spaces, batch encodings,
  action checks, addresses, keys, stats); imports neither of the other two.
- ``remoteenv/sim/``: the sim process; imports only ``remoteenv.wire``.
- ``remoteenv/agent/``: the agent process (connections, launcher, attach,
  the session, restarts, errors); the env classes
  (:mod:`remoteenv.remote_env`, :mod:`remoteenv.vector_env`) sit on top.
"""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Any

from remoteenv._source_scenes import ensure_scenes_package
from remoteenv.wire.protocol import PROTOCOL_VERSION

__version__ = "0.1.0"

#: Public name -> module that defines it; loaded on first attribute access.
_LAZY = {
    "OpenAIRemoteEnv": "remoteenv.remote_env",
    "RemoteVectorEnv": "remoteenv.vector_env",
    "Launcher": "remoteenv.agent.launch.launcher",
    "SimGroup": "remoteenv.agent.launch.sim_group",
    "RemoteEnvError": "remoteenv.agent.errors",
    "RemoteEnvTimeout": "remoteenv.agent.errors",
    "LaunchError": "remoteenv.agent.errors",
    "LimitError": "remoteenv.agent.errors",
    "SceneError": "remoteenv.agent.errors",
    "SceneArgumentError": "remoteenv.agent.errors",
    "SceneAttributeError": "remoteenv.agent.errors",
    "UnsendableValueError": "remoteenv.agent.errors",
    "RemoteProtocolError": "remoteenv.agent.errors",
    "InvalidActionError": "remoteenv.agent.errors",
    "StateError": "remoteenv.agent.errors",
    "SimDiedError": "remoteenv.agent.errors",
    "prestart": "remoteenv.startup",
}
#: Submodules reachable as attributes (``remoteenv.protocol``, ...), loaded on first access.
_SUBMODULES = frozenset(
    {
        "protocol",
        "remote_env",
        "vector_env",
        "controllers",
        "sim",
        "wire",
        "agent",
        "cli",
        "benchmarks",
        "compliance",
        "delays",
        "wrappers",
        "latency",
        "integrations",
        "scene_controllers",
    }
)

if TYPE_CHECKING:
    from remoteenv.agent.errors import (
        InvalidActionError,
        LaunchError,
        LimitError,
        RemoteEnvError,
        RemoteEnvTimeout,
        RemoteProtocolError,
        SceneArgumentError,
        SceneAttributeError,
        SceneError,
        SimDiedError,
        StateError,
        UnsendableValueError,
    )
    from remoteenv.agent.launch.launcher import Launcher
    from remoteenv.agent.launch.sim_group import SimGroup
    from remoteenv.remote_env import OpenAIRemoteEnv
    from remoteenv.startup import prestart
    from remoteenv.vector_env import RemoteVectorEnv


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is not None:
        value = getattr(importlib.import_module(module), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"remoteenv.{name}")
    raise AttributeError(f"module 'remoteenv' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | _SUBMODULES)


ensure_scenes_package()
#: Gymnasium id of each shipped scene, by scene name (importing a scene package registers its id).
SHIPPED_SCENES: dict[str, str] = {
    name: importlib.import_module(f"remoteenv.scenes.{name}").ENV_ID for name in ("cartpole", "reacher", "hexapod")
}

__all__ = [
    "InvalidActionError",
    "LaunchError",
    "Launcher",
    "LimitError",
    "OpenAIRemoteEnv",
    "PROTOCOL_VERSION",
    "RemoteEnvError",
    "RemoteEnvTimeout",
    "RemoteProtocolError",
    "RemoteVectorEnv",
    "SHIPPED_SCENES",
    "SceneArgumentError",
    "SceneAttributeError",
    "SceneError",
    "SimDiedError",
    "SimGroup",
    "StateError",
    "UnsendableValueError",
    "prestart",
    "scene_path",
]


def scene_path(name: str) -> str:
    """Path of a shipped scene script: ``scene_path("cartpole")``."""
    import remoteenv.scenes as scenes

    path = os.path.join(os.path.dirname(scenes.__file__), name, f"{name}_scene.py")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no shipped scene named {name!r} (looked for {path})")
    return path
