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

Camera images: RLlib's default CNN takes float images, and a uint8 image
fails inside the env runner (``Input type (unsigned char) and bias type
(float) should be the same``) while ``train()`` reports 0 env steps. So the
creator hands RLlib every uint8 ``H x W x C`` image scaled to float32 in
[0, 1] (in a ``Dict`` too), with Gymnasium's ``TransformObservation``
wrapper (its vector twin for a vector env); ``register_envs(scale_images=False)``
keeps them uint8 for a connector or model of your own. RLlib's default
models take one ``Box``, not a ``Dict``: a ``state_pixels`` observation
trains with RLlib's own ``FlattenObservations`` env-to-module connector (or
an RLModule of yours), see docs/training.md.

Needs ``ray[rllib]`` (``pip install torch==2.13.0 "ray[rllib]==2.60.0"``,
torch first); importing this module does not import Ray.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from remoteenv.registration import find_spec, remote_env_ids


def is_uint8_image(space: spaces.Space) -> bool:
    """A uint8 ``H x W x C`` Box in [0, 255] (a camera image)."""
    return (
        isinstance(space, spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) == 3
        and bool((space.low == 0).all() and (space.high == 255).all())
    )


def float_image_space(space: spaces.Space) -> spaces.Space | None:
    """``space`` with every uint8 image (alone or in a flat Dict) as float32 in
    [0, 1]; None if it has no such image."""
    if is_uint8_image(space):
        return spaces.Box(0.0, 1.0, space.shape, dtype=np.float32)
    if isinstance(space, spaces.Dict) and any(is_uint8_image(s) for s in space.spaces.values()):
        return spaces.Dict({k: float_image_space(s) or s for k, s in space.spaces.items()})
    return None


def _scaled(obs: Any) -> Any:
    """An observation (or batch) with its uint8 images as float32 in [0, 1]."""
    if isinstance(obs, dict):
        return {k: _scaled(v) for k, v in obs.items()}
    if isinstance(obs, np.ndarray) and obs.dtype == np.uint8:
        return obs.astype(np.float32) / np.float32(255.0)
    return obs


def scale_images(env: Any) -> Any:
    """``env`` (an env or a vector env) with its uint8 images scaled to float32
    in [0, 1] (Gymnasium's ``TransformObservation``), or ``env`` itself if its
    observations hold no image."""
    if isinstance(env, gym.vector.VectorEnv):
        single = float_image_space(env.single_observation_space)
        if single is None:
            return env
        return gym.wrappers.vector.TransformObservation(env, _scaled, single_observation_space=single)
    space = float_image_space(env.observation_space)
    return env if space is None else gym.wrappers.TransformObservation(env, _scaled, space)


class EnvCreator:
    """RLlib's env creator for one registered id: ``creator(env_config)``.

    Called with the runner's ``EnvContext`` (a dict of env kwargs): a single
    env; with ``num_envs`` in it (RLlib's ``vector_entry_point`` mode) a
    vector env of that many worlds. Pickles as the module path and the spec,
    so a process that never imported the id's package can call it.
    ``scale_images``: hand camera images to RLlib as float32 in [0, 1]
    (:func:`scale_images`; RLlib's default CNN takes no uint8).
    """

    def __init__(self, spec: EnvSpec, scale_images: bool = True) -> None:
        self.spec = spec
        self.scale_images = scale_images

    def __call__(self, env_config: Any = None) -> Any:
        kwargs = dict(env_config or {})
        num_envs = kwargs.pop("num_envs", None)
        env: Any
        if num_envs is None:
            env = gym.make(self.spec, **kwargs)
        else:
            env = gym.make_vec(self.spec, num_envs=int(num_envs), vectorization_mode="vector_entry_point", **kwargs)
        try:
            return scale_images(env) if self.scale_images else env
        except BaseException:
            env.close()
            raise

    def __repr__(self) -> str:
        return f"EnvCreator({self.spec.id!r})"


def register_envs(*env_ids: str, scale_images: bool = True) -> list[str]:
    """Register ``env_ids`` (default: every remote env id registered in this
    process) with Ray Tune's env registry under their plain ids, so that
    ``config.environment(id)`` works in RLlib's env runners. ``"module:id"``
    imports ``module`` first and registers ``id``. Returns the ids registered.
    ``scale_images=False`` hands camera images to RLlib as uint8 (for a
    connector or model of your own) instead of float32 in [0, 1].

    Call it in the driver, before or after ``ray.init``, after importing the
    env packages whose ids you use (``import my_arm``) or naming them here."""
    from ray.tune.registry import register_env

    registered = []
    for env_id in env_ids or tuple(remote_env_ids()):
        spec = find_spec(env_id)
        register_env(spec.id, EnvCreator(spec, scale_images))
        registered.append(spec.id)
    return registered


__all__ = ["EnvCreator", "float_image_space", "is_uint8_image", "register_envs", "scale_images"]
