"""Stable-Baselines3 on remote envs: an SB3 ``VecEnv`` over a Gymnasium vector env.

Runs in the agent process. SB3 does not accept Gymnasium vector envs; it
wants its own ``VecEnv`` API. :class:`SB3VecEnv` adapts
:class:`remoteenv.vector_env.RemoteVectorEnv` (or any Gymnasium 1.x
``VectorEnv``) to it::

    from stable_baselines3 import PPO
    from remoteenv.integrations.sb3 import SB3VecEnv, make_sb3_vec_env

    venv = make_sb3_vec_env("remoteenv/CartPole-v0", num_envs=8)
    PPO("MlpPolicy", venv).learn(100_000)
    venv.close()

What SB3 expects and the adapter provides:

- ``step_wait`` returns ``(obs, rewards float32 (N,), dones bool (N,), infos
  list of N dicts)`` with ``dones = terminated | truncated``.
- When env ``i`` is done, ``obs[i]`` is already the first observation of its
  next episode, ``infos[i]["terminal_observation"]`` is the last observation
  of the finished one, and ``infos[i]["TimeLimit.truncated"]`` is
  ``truncated and not terminated`` (SB3 then bootstraps the value).
- ``reset()`` uses the seeds of ``seed()`` and the options of
  ``set_options()`` once, as SB3's own vec envs do.

The vector env's autoreset mode is read from its ``metadata["autoreset_mode"]``:
with ``SAME_STEP`` the finished episode's last observation comes from
``infos["final_obs"]`` (and its last info from ``infos["final_info"]``; the
new episode's reset info goes to ``reset_infos``); with ``NEXT_STEP`` or ``DISABLED`` the adapter resets
the finished envs at once with ``reset(options={"reset_mask": dones})``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from remoteenv.registration import make_vector_env


def split_infos(infos: dict[str, Any], num_envs: int) -> list[dict[str, Any]]:
    """Turn a Gymnasium vector ``infos`` map (``key -> batched values`` with
    ``_key -> mask``) into one dict per env, keeping only the entries each env set."""
    out: list[dict[str, Any]] = [{} for _ in range(num_envs)]
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        mask = infos.get(f"_{key}")
        if isinstance(value, dict):
            for i, sub in enumerate(split_infos(value, num_envs)):
                if (mask is None or mask[i]) and sub:
                    out[i][key] = sub
            continue
        for i in range(num_envs):
            if mask is None or mask[i]:
                out[i][key] = value[i]
    return out


def _item(value: Any, i: int) -> Any:
    """Env ``i``'s part of a batched observation (array, or dict/tuple of arrays)."""
    if isinstance(value, dict):
        return {k: _item(v, i) for k, v in value.items()}
    if isinstance(value, tuple):
        return tuple(_item(v, i) for v in value)
    return np.array(value[i], copy=True)


def _put(target: Any, source: Any, mask: np.ndarray) -> Any:
    """``target`` with the rows of ``mask`` replaced by those of ``source``."""
    if isinstance(target, dict):
        return {k: _put(target[k], source[k], mask) for k in target}
    if isinstance(target, tuple):
        return tuple(_put(t, s, mask) for t, s in zip(target, source))
    out = np.array(target, copy=True)
    out[mask] = np.asarray(source)[mask]
    return out


class SB3VecEnv(VecEnv):
    """An SB3 ``VecEnv`` that drives a Gymnasium vector env (see the module docstring).

    Args:
        venv: the vector env, e.g. ``RemoteVectorEnv`` or
            ``gymnasium.make_vec("remoteenv/CartPole-v0", 8)``. The adapter owns
            it: :meth:`close` closes it.
    """

    def __init__(self, venv: VectorEnv) -> None:
        self.venv = venv
        mode = venv.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        self.autoreset_mode = mode if isinstance(mode, AutoresetMode) else AutoresetMode(mode)
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)

    # ------------------------------------------------------------ stepping

    def reset(self) -> Any:
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._options[0] if self._options and self._options[0] else None
        if any(o != self._options[0] for o in self._options):
            raise ValueError(
                "SB3VecEnv passes one options map to the vector env's reset; set the same options for every env"
            )
        obs, infos = self.venv.reset(seed=cast(Any, seeds), options=options)  # one seed per world
        self.reset_infos = split_infos(infos, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        per_env = split_infos(infos, self.num_envs)
        if dones.any():
            if self.autoreset_mode == AutoresetMode.SAME_STEP:
                final_obs = infos["final_obs"]
                final_info = infos.get("final_info")
                finals = split_infos(final_info, self.num_envs) if final_info else per_env
                for i in np.flatnonzero(dones).tolist():
                    self.reset_infos[i] = {k: v for k, v in per_env[i].items() if k not in ("final_obs", "final_info")}
                    per_env[i] = dict(finals[i])
                    per_env[i]["terminal_observation"] = final_obs[i]
            else:
                for i in np.flatnonzero(dones).tolist():
                    per_env[i]["terminal_observation"] = _item(obs, i)
                reset_obs, reset_infos = self.venv.reset(options={"reset_mask": dones})
                obs = _put(obs, reset_obs, dones)
                for i, info in enumerate(split_infos(reset_infos, self.num_envs)):
                    if dones[i]:
                        self.reset_infos[i] = info
        for i in range(self.num_envs):
            per_env[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, np.asarray(rewards, dtype=np.float32), dones, per_env

    def close(self) -> None:
        self.venv.close()

    # ------------------------------------------------------------ attributes

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.render_mode != "rgb_array":
            return [None] * self.num_envs
        frames = self.venv.render()
        if frames is None:
            return [None] * self.num_envs
        return list(cast(Sequence[Any], frames))

    def _per_env(self, name: str) -> list[Any]:
        if name == "render_mode":
            return [getattr(self.venv, "render_mode", None)] * self.num_envs
        getter = getattr(self.venv, "get_attr", None)
        if getter is not None:
            try:
                return list(getter(name))
            except (AttributeError, NotImplementedError):
                pass
        return [getattr(self.venv, name)] * self.num_envs

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        values = self._per_env(attr_name)
        return [values[i] for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set ``attr_name`` to ``value`` on the envs ``indices`` (all by default);
        on a :class:`remoteenv.RemoteVectorEnv` that is the scene's attribute in each world."""
        setter = getattr(self.venv, "set_attr", None)
        if setter is None:
            raise AttributeError(f"{type(self.venv).__name__} cannot set per-env attributes")
        targets = list(self._get_indices(indices))
        if targets == list(range(self.num_envs)):
            setter(attr_name, [value] * self.num_envs)
        elif hasattr(self.venv, "set_attr_at"):
            self.venv.set_attr_at(targets, attr_name, [value] * len(targets))
        else:
            # Any Gymnasium vector env: write back the current values elsewhere.
            values = self._per_env(attr_name)
            for i in targets:
                values[i] = value
            setter(attr_name, values)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call ``method_name`` on the envs ``indices`` only (all by default), one result each."""
        targets = list(self._get_indices(indices))
        if targets != list(range(self.num_envs)):
            if hasattr(self.venv, "call_at"):
                return list(self.venv.call_at(targets, method_name, *method_args, **method_kwargs))
            envs = getattr(self.venv, "envs", None)
            if envs is not None:  # an in-process vector env: call its sub-envs one by one
                return [envs[i].get_wrapper_attr(method_name)(*method_args, **method_kwargs) for i in targets]
            raise NotImplementedError(f"{type(self.venv).__name__} cannot call a method on some envs only")
        caller = getattr(self.venv, "call", None)
        if caller is None:
            raise AttributeError(f"{type(self.venv).__name__} cannot call per-env methods")
        return list(caller(method_name, *method_args, **method_kwargs))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        # Remote worlds are not Gymnasium envs wrapped on this side; sub-envs of
        # an in-process vector env are looked at one by one.
        envs: Iterable[Any] | None = getattr(self.venv, "envs", None)
        if envs is None:
            return [False for _ in self._get_indices(indices)]
        envs = list(envs)
        out = []
        for i in self._get_indices(indices):
            env, wrapped = envs[i], False
            while isinstance(env, gym.Wrapper):
                wrapped = wrapped or isinstance(env, wrapper_class)
                env = env.env
            out.append(wrapped)
        return out


def make_sb3_vec_env(env_id: str, num_envs: int, **kwargs: Any) -> SB3VecEnv:
    """An SB3 ``VecEnv`` of ``num_envs`` remote envs of ``env_id``, via the id's
    registered vector entry point (:class:`remoteenv.vector_env.RemoteVectorEnv`).
    ``kwargs`` go to the vector env (e.g. ``seed``, ``max_episode_steps`` or scene kwargs).

    Unless ``kwargs`` name an ``autoreset_mode``, the vector env is built with
    ``SAME_STEP`` when its entry point takes that parameter: an episode's end
    and the next episode's reset then cost one round trip, not two. SB3 sees
    the same obs, rewards, dones and infos in either mode."""
    return SB3VecEnv(make_vector_env(env_id, num_envs, AutoresetMode.SAME_STEP, **kwargs))


__all__ = ["SB3VecEnv", "make_sb3_vec_env", "split_infos"]
