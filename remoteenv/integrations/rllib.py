"""RLlib on remote envs: plain ids in its env runners, with one call in the driver.

Runs in the agent process (the driver) and in RLlib's env runners. The
runners are fresh processes that never import remoteenv, so a plain id
fails there (Gymnasium 1.x has no plugin hook that would import a package
for its namespace): ``NamespaceNotFound: Namespace remoteenv not found`` in
the runner's log, while the driver reports only that the runners could not
be built. RLlib, however, looks every configured env name up in Ray Tune's
env registry first, which the runners read from the cluster, so registering
the ids there once in the driver is enough::

    import remoteenv.integrations.rllib
    from ray.rllib.algorithms.ppo import PPOConfig

    remoteenv.integrations.rllib.register_envs()        # every remote env id known to this process
    config = PPOConfig().environment("remoteenv/CartPole-v0", env_config={"seed": 0})

Each registered creator carries the id's Gymnasium spec (entry points and
the scene script's path), so a runner builds the env without importing the
package that registered it. ``env_config`` holds the env's keyword
arguments. With ``gym_env_vectorize_mode="vector_entry_point"`` a runner
asks for its ``num_envs_per_env_runner`` worlds at once and gets one
:class:`~remoteenv.vector_env.RemoteVectorEnv` (``NEXT_STEP`` autoreset,
which RLlib's runners expect); otherwise one remote env per world.

Needs ``ray[rllib]`` (``pip install torch==2.13.0 "ray[rllib]==2.60.0"``,
torch first); importing this module does not import Ray.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

from remoteenv.registration import find_spec, remote_env_ids


class EnvCreator:
    """RLlib's env creator for one registered id: ``creator(env_config)``.

    Called with the runner's ``EnvContext`` (a dict of env kwargs): a single
    env; with ``num_envs`` in it (RLlib's ``vector_entry_point`` mode) a
    vector env of that many worlds. Pickles as the module path and the spec,
    so a process that never imported the id's package can call it.
    """

    def __init__(self, spec: EnvSpec) -> None:
        self.spec = spec

    def __call__(self, env_config: Any = None) -> Any:
        kwargs = dict(env_config or {})
        num_envs = kwargs.pop("num_envs", None)
        if num_envs is None:
            return gym.make(self.spec, **kwargs)
        return gym.make_vec(self.spec, num_envs=int(num_envs), vectorization_mode="vector_entry_point", **kwargs)

    def __repr__(self) -> str:
        return f"EnvCreator({self.spec.id!r})"


def register_envs(*env_ids: str) -> list[str]:
    """Register ``env_ids`` (default: every remote env id registered in this
    process) with Ray Tune's env registry under their plain ids, so that
    ``config.environment(id)`` works in RLlib's env runners. ``"module:id"``
    imports ``module`` first and registers ``id``. Returns the ids registered.

    Call it in the driver, before or after ``ray.init``, after importing the
    env packages whose ids you use (``import my_arm``) or naming them here."""
    from ray.tune.registry import register_env

    registered = []
    for env_id in env_ids or tuple(remote_env_ids()):
        spec = find_spec(env_id)
        register_env(spec.id, EnvCreator(spec))
        registered.append(spec.id)
    return registered


__all__ = ["EnvCreator", "register_envs"]
