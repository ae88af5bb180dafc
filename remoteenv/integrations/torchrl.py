"""TorchRL on remote envs: a batched TorchRL env over one ``RemoteVectorEnv``.

Runs in the agent process. TorchRL's ``GymWrapper`` takes a Gymnasium vector
env as a batched env, but only in the ``SAME_STEP`` or ``DISABLED`` autoreset
modes; :class:`~remoteenv.vector_env.RemoteVectorEnv` defaults to Gymnasium's
``NEXT_STEP`` (which Gymnasium's own vector wrappers need).
:func:`make_torchrl_env` builds the vector env with ``DISABLED``, the mode
TorchRL prefers: a step that ends an episode returns its last observation,
and TorchRL then resets the finished worlds alone (``reset_mask``), as it
does for its own batched envs. (TorchRL 0.14's ``SAME_STEP`` path fails on
``Dict`` observations at the first episode end, and measured slower here on
``Box`` ones too.) Camera images are named as TorchRL's ``GymEnv`` names
them: an image alone ``"pixels"``; a Dict's ``"state"`` ``"observation"``,
its ``"pixels"`` as they are::

    from remoteenv.integrations.torchrl import make_torchrl_env

    env = make_torchrl_env("remoteenv/CartPole-v0", num_envs=8)
    rollout = env.rollout(100, break_when_any_done=False)   # batch (8, 100)
    env.close()

A single remote env needs no adapter: ``torchrl.envs.GymEnv("remoteenv/CartPole-v0")``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from torchrl.envs import GymWrapper, RenameTransform, TransformedEnv

from remoteenv.registration import make_vector_env


def is_image_space(space: spaces.Space) -> bool:
    """An image as TorchRL's ``GymEnv`` recognises one: a uint8 ``H x W x 3`` Box in [0, 255]."""
    return (
        isinstance(space, spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) == 3
        and space.shape[-1] == 3
        and bool((space.low == 0).all() and (space.high == 255).all())
    )


def make_torchrl_env(
    env_id: str, num_envs: int = 1, *, wrapper_kwargs: Mapping[str, Any] | None = None, **kwargs: Any
) -> Any:
    """A TorchRL env of batch size ``(num_envs,)`` over ``num_envs`` remote envs of
    ``env_id`` (``"module:id"`` imports ``module`` first). ``kwargs`` go to the
    vector env (e.g. ``seed``, ``envs_per_process``, scene kwargs such as
    ``obs_mode``; an ``autoreset_mode`` of your own must be ``SAME_STEP`` or
    ``DISABLED``), ``wrapper_kwargs`` to TorchRL's ``GymWrapper`` (e.g.
    ``device``). An image observation comes under ``"pixels"`` (a
    ``TransformedEnv`` renaming ``GymWrapper``'s ``"observation"``).
    Closing the TorchRL env closes the vector env and its sims."""
    venv = make_vector_env(env_id, num_envs, AutoresetMode.DISABLED, **kwargs)
    try:
        env = GymWrapper(venv, **dict(wrapper_kwargs or {}))
        if is_image_space(venv.single_observation_space):
            env = TransformedEnv(env, RenameTransform(["observation"], ["pixels"]))
        return env
    except BaseException:
        venv.close()
        raise


__all__ = ["is_image_space", "make_torchrl_env"]
