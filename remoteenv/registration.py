"""The Gymnasium ids of remote envs, as the library adapters build them.

Runs in the agent process. A remote env's id is registered with Gymnasium
(importing its package registers it: ``remoteenv`` for the shipped scenes,
``my_arm`` for a package ``new-scene`` wrote) with remoteenv's entry points;
the adapters for Stable-Baselines3 (:mod:`remoteenv.integrations.sb3`), TorchRL
(:mod:`remoteenv.integrations.torchrl`) and RLlib (:mod:`remoteenv.integrations.rllib`) find and build
them through this module.

Autoreset: :class:`~remoteenv.vector_env.RemoteVectorEnv` defaults to
Gymnasium's own default, ``NEXT_STEP``, which Gymnasium's vector wrappers
(``NormalizeObservation`` and the other stateful ones refuse ``SAME_STEP``)
and RLlib's env runners expect. Stable-Baselines3's and TorchRL's adapters
build theirs with ``SAME_STEP`` (TorchRL's ``GymWrapper`` refuses
``NEXT_STEP``; SB3 wants the next episode's first observation at once):
:func:`make_vector_env` with that mode.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec, load_env_creator
from gymnasium.vector import AutoresetMode, VectorEnv

#: The entry points a remote env's registration names.
ENTRY_POINT = "remoteenv.remote_env:OpenAIRemoteEnv"
VECTOR_ENTRY_POINT = "remoteenv.vector_env:RemoteVectorEnv"


def find_spec(env_id: str) -> EnvSpec:
    """The registered spec of ``env_id``; ``"module:id"`` imports ``module``
    first, as ``gymnasium.make`` does (``gymnasium.error.Error`` if unknown)."""
    module, _, name = env_id.rpartition(":")
    if module:
        importlib.import_module(module)
    return gym.spec(name)


def is_remote(spec: EnvSpec) -> bool:
    """Whether ``spec`` makes a remote env (remoteenv's entry points)."""
    return spec.entry_point == ENTRY_POINT or spec.vector_entry_point == VECTOR_ENTRY_POINT


def remote_env_ids() -> list[str]:
    """Every remote env id registered in this process (the shipped scenes' and
    those of every env package imported so far), sorted."""
    return sorted(env_id for env_id, spec in gym.registry.items() if is_remote(spec))


def takes_autoreset_mode(env_id: str) -> bool:
    """Whether ``env_id``'s registered vector entry point has an ``autoreset_mode`` parameter."""
    try:
        entry = find_spec(env_id).vector_entry_point
    except (ImportError, gym.error.Error):  # gym.make_vec will say what is wrong with the id
        return False
    if entry is None:
        return False
    creator = load_env_creator(entry) if isinstance(entry, str) else entry
    try:
        return "autoreset_mode" in inspect.signature(creator).parameters
    except (TypeError, ValueError):  # no signature to read
        return False


def make_vector_env(env_id: str, num_envs: int, default_mode: AutoresetMode, /, **kwargs: Any) -> VectorEnv:
    """``gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point", **kwargs)``
    with ``autoreset_mode=default_mode`` unless ``kwargs`` name one (or the entry point takes none)."""
    if "autoreset_mode" not in kwargs and takes_autoreset_mode(env_id):
        kwargs["autoreset_mode"] = default_mode
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)


__all__ = [
    "ENTRY_POINT",
    "VECTOR_ENTRY_POINT",
    "find_spec",
    "is_remote",
    "make_vector_env",
    "remote_env_ids",
    "takes_autoreset_mode",
]
