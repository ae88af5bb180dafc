"""TorchRL on remote envs: a batched TorchRL env over one ``RemoteVectorEnv``.

Runs in the agent process. TorchRL's ``GymWrapper`` takes a Gymnasium vector
env as a batched env, but only in the ``SAME_STEP`` or ``DISABLED`` autoreset
modes; :class:`~remoteenv.vector_env.RemoteVectorEnv` defaults to Gymnasium's
``NEXT_STEP`` (which Gymnasium's own vector wrappers need). :func:`make_torchrl_env`
builds the vector env with ``SAME_STEP`` (one round trip per step, an
episode's end included; TorchRL reads the finished episode's last
observation from ``final_obs``) and wraps it::

    from remoteenv.integrations.torchrl import make_torchrl_env

    env = make_torchrl_env("remoteenv/CartPole-v0", num_envs=8)
    rollout = env.rollout(100, break_when_any_done=False)   # batch (8, 100)
    env.close()

A single remote env needs no adapter: ``torchrl.envs.GymEnv("remoteenv/CartPole-v0")``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gymnasium.vector import AutoresetMode
from torchrl.envs import GymWrapper

from remoteenv.registration import make_vector_env


def make_torchrl_env(
    env_id: str, num_envs: int = 1, *, wrapper_kwargs: Mapping[str, Any] | None = None, **kwargs: Any
) -> Any:
    """A TorchRL env of batch size ``(num_envs,)`` over ``num_envs`` remote envs of
    ``env_id`` (``"module:id"`` imports ``module`` first). ``kwargs`` go to the
    vector env (e.g. ``seed``, ``envs_per_process``, scene kwargs; an
    ``autoreset_mode`` of your own must be ``SAME_STEP`` or ``DISABLED``),
    ``wrapper_kwargs`` to TorchRL's ``GymWrapper`` (e.g. ``device``).
    Closing the TorchRL env closes the vector env and its sims."""
    venv = make_vector_env(env_id, num_envs, AutoresetMode.SAME_STEP, **kwargs)
    try:
        return GymWrapper(venv, **dict(wrapper_kwargs or {}))
    except BaseException:
        venv.close()
        raise


__all__ = ["make_torchrl_env"]
