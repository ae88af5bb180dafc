"""Delay-aware observations: the env's observation followed by the last ``k`` actions.

Under action delay a policy that sees only the (delayed) state cannot tell
which of its own actions are still on their way; adding them to the
observation restores the Markov property (the state augmentation of
Ramstedt & Pal 2019 and the action buffer of Bouteiller et al. 2021; rtgym's
``act_in_obs``). Works on any Gymnasium env, remote or in-process.

Layout of the new observation, for a Box of values (one flat :class:`~gymnasium.spaces.Box`)::

    [ env obs (flattened) | a_{t-k+1} ... a_t (oldest first) | alpha | omega | latency ]

(``alpha``, ``omega`` and ``latency`` each only when asked for). With random
delays this is the state of Bouteiller et al.'s RDMDP: the delayed
observation, the action buffer, the observation's age ``omega`` and
``alpha``, the age of the action that was in force during the tick that
produced the observation: that action is the buffer's entry
``k - 1 - omega - alpha`` (counting from 0, oldest first).

How long a buffer: ``k = max alpha + max omega + 1`` = the largest action
delay plus the largest observation delay plus one
(:func:`required_history`) holds, at every step, the action in force during
the returned observation's tick and every action sent since; one less
misses the in-force action whenever its age and the observation's are both
at their largest. (For a constant action delay ``K`` without observation
delay, ``k = K`` is enough to predict: the in-force action of the returned
tick is replaced at the next one for sure.) With ``include_alpha=True`` a
buffer shorter than that, on an env that reports its delays
(``env.unwrapped.handshake``), warns.

For images and Dicts the action features stay a separate vector input (a
network reads pixels and features differently; flattening an image into an
MLP's input would lose what a CNN needs) in a :class:`~gymnasium.spaces.Dict`::

    image Box (uint8, H x W x C)  ->  {"pixels": image, "history": features}
    Dict {"state": ..., ...}      ->  {"state": ..., ..., "history": features}

with ``features`` the flat ``[ a_{t-k+1} ... a_t | alpha | omega | latency ]`` (float32; each
of the last three only when asked for).

- Observation spaces: a :class:`~gymnasium.spaces.Box` of any shape
  (flattened in C order; an image as above), or a flat ``Dict`` (no nested
  Dict or Tuple) without a ``"history"`` key. Anything else raises ``TypeError``.
- Action spaces: :class:`~gymnasium.spaces.Box` (each action flattened, as
  passed to ``step``: put ``ClipAction`` outside this wrapper to record
  clipped actions) and :class:`~gymnasium.spaces.Discrete` (one-hot of
  length ``n``). Anything else raises ``TypeError``.
- After a reset the history is all zeros (for Discrete: no action yet); the
  space's bounds for an action slot are the action bounds widened to include 0.
- ``include_alpha=True`` adds ``info["obs_action_delay_ticks"]`` (alpha of the
  returned observation), ``include_obs_delay=True`` ``info["obs_delay_ticks"]``
  (omega): both known when the step returns, 0 when absent (the reset).
- ``include_latency=True`` adds one feature: the ``info["latency_ticks"]``
  of the step (or reset) that returned this observation, 0 when it is absent
  or None. In delayed lock-step that is the latency of the action in force
  during the step's tick, known once that action arrived (0 while the
  default acts); in real time the latency of the step's own action, known
  when it took effect. Neither tells a delay that has not elapsed.
- dtype: the observation's dtype promoted with float32 (float32 for float32 observations).
"""

from __future__ import annotations

import math
import warnings
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

__all__ = ["HISTORY_KEY", "PIXELS_KEY", "ActionHistory", "ActionHistoryVector", "is_image", "required_history"]

#: The key of the action features in a Dict observation, and of an image observation.
HISTORY_KEY, PIXELS_KEY = "history", "pixels"

#: The info keys of the optional features, in the order they are appended.
_FEATURE_KEYS = ("obs_action_delay_ticks", "obs_delay_ticks", "latency_ticks")


def required_history(action_delay: Any, obs_delay: Any = 0) -> int:
    """The buffer length ``k`` that holds the action in force during the
    returned observation's tick at any delays of these models (ints or
    :mod:`remoteenv.delays` specs in ticks): the largest action delay plus
    the largest observation delay plus one."""
    from remoteenv.wire.delays.delay_specs import TICKS, as_delay

    return int(as_delay(action_delay, TICKS).max) + int(as_delay(obs_delay, TICKS).max) + 1


def _feature_keys(include_alpha: bool, include_obs_delay: bool, include_latency: bool) -> tuple[str, ...]:
    return tuple(key for key, on in zip(_FEATURE_KEYS, (include_alpha, include_obs_delay, include_latency)) if on)


def _check_length(env: Any, k: int, include_alpha: bool, owner: str) -> None:
    """Warn when ``include_alpha`` is asked of a buffer too short for the delays ``env`` reports."""
    hs = getattr(getattr(env, "unwrapped", env), "handshake", None)
    if not include_alpha or hs is None:
        return
    try:
        need = int(hs.action_delay) + int(hs.obs_delay) + 1
    except (AttributeError, TypeError, ValueError):
        return
    if k < need:
        warnings.warn(
            f"{owner}(k={k}, include_alpha=True): the env's delays reach {hs.action_delay} ticks (actions) "
            f"and {hs.obs_delay} (observations), so the action in force at the observation's tick can be "
            f"{need - 1} steps old: keep k >= {need} (remoteenv.latency.action_history.required_history)",
            stacklevel=3,
        )


def is_image(space: spaces.Space) -> bool:
    """Whether ``space`` is an image: a uint8 Box of 3 dimensions (H x W x C, as SB3's CNNs take it)."""
    return isinstance(space, spaces.Box) and space.dtype == np.uint8 and len(space.shape) == 3


class _ActionEncoder:
    """Flat float features of an action: a Box flattened, a Discrete one-hot."""

    def __init__(self, space: spaces.Space, dtype: np.dtype, owner: str) -> None:
        self.space = space
        self.dtype = dtype
        if isinstance(space, spaces.Box):
            self.size = int(np.prod(space.shape, dtype=np.int64))
            self.low = np.minimum(space.low.reshape(-1), 0).astype(dtype)
            self.high = np.maximum(space.high.reshape(-1), 0).astype(dtype)
        elif isinstance(space, spaces.Discrete):
            self.size = int(space.n)
            self.low = np.zeros(self.size, dtype=dtype)
            self.high = np.ones(self.size, dtype=dtype)
        else:
            raise TypeError(f"{owner} supports Box and Discrete action spaces, got {space}")

    def encode(self, actions: Any, n: int) -> np.ndarray:
        """``(n, size)`` features of ``n`` actions (a batch as a vector env takes it)."""
        out = np.zeros((n, self.size), dtype=self.dtype)
        if isinstance(self.space, spaces.Box):
            arr = np.asarray(actions, dtype=self.dtype)
            if arr.size != n * self.size:
                raise ValueError(f"actions of shape {arr.shape} do not fit {n} x {self.space}")
            out[:] = arr.reshape(n, self.size)
            return out
        assert isinstance(self.space, spaces.Discrete)
        idx = np.asarray(actions).reshape(-1)
        if idx.shape != (n,) or idx.dtype.kind not in "iu":
            raise ValueError(f"actions {np.asarray(actions)!r:.100} do not fit {n} x {self.space}")
        idx = idx.astype(np.int64) - int(self.space.start)
        bad = (idx < 0) | (idx >= self.size)
        if bad.any():
            raise ValueError(f"action {int(idx[bad][0]) + int(self.space.start)} is outside {self.space}")
        out[np.arange(n), idx] = 1
        return out


def _augmented_space(
    obs_space: spaces.Space, encoder: _ActionEncoder, k: int, features: int, dtype: np.dtype
) -> spaces.Space:
    low = [np.tile(encoder.low, k), np.zeros(features, dtype=dtype)]
    high = [np.tile(encoder.high, k), np.full(features, np.inf, dtype=dtype)]
    if _separate(obs_space):
        vector = spaces.Box(np.concatenate(low), np.concatenate(high), dtype=dtype)
        inputs = dict(obs_space.spaces) if isinstance(obs_space, spaces.Dict) else {PIXELS_KEY: obs_space}
        return spaces.Dict({**inputs, HISTORY_KEY: vector})
    assert isinstance(obs_space, spaces.Box)
    low.insert(0, obs_space.low.reshape(-1).astype(dtype))
    high.insert(0, obs_space.high.reshape(-1).astype(dtype))
    return spaces.Box(np.concatenate(low), np.concatenate(high), dtype=dtype)


def _separate(obs_space: spaces.Space) -> bool:
    """Whether the action features go beside the observation (a Dict) rather than after it."""
    return isinstance(obs_space, spaces.Dict) or is_image(obs_space)


def _check_spaces(obs_space: spaces.Space, k: int, owner: str) -> np.dtype:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise ValueError(f"{owner} needs k >= 0 actions to keep, got {k!r:.60}")
    if isinstance(obs_space, spaces.Dict):
        nested = [key for key, sub in obs_space.spaces.items() if isinstance(sub, (spaces.Dict, spaces.Tuple))]
        if nested or HISTORY_KEY in obs_space.spaces:
            raise TypeError(
                f"{owner} supports flat Dict observations without a {HISTORY_KEY!r} key, got {obs_space}; "
                f"flatten the nested entries {nested} or rename the key"
            )
        return np.dtype(np.float32)
    if not isinstance(obs_space, spaces.Box):
        raise TypeError(
            f"{owner} supports Box and Dict observation spaces, got {obs_space}; "
            "flatten it first (gymnasium.wrappers.FlattenObservation)"
        )
    return np.dtype(np.float32) if is_image(obs_space) else np.result_type(obs_space.dtype, np.float32)


def _latency(value: Any) -> float:
    """A feature from an info value (ticks): 0 when absent, None or not finite."""
    if value is None:
        return 0.0
    try:
        ticks = float(value)
    except (TypeError, ValueError):
        return 0.0
    return ticks if math.isfinite(ticks) else 0.0


class ActionHistory(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The env's observation followed by its last ``k`` actions (see the module docs).

    Args:
        env: an env with a Box or flat Dict observation space and a Box or Discrete action space.
        k: how many past actions to append (0 appends none); see
            :func:`required_history` for how many the delays need.
        include_alpha: append ``info["obs_action_delay_ticks"]``, the age of
            the action in force during the returned observation's tick.
        include_obs_delay: append ``info["obs_delay_ticks"]``, the returned observation's age.
        include_latency: append ``info["latency_ticks"]`` (leak-free, see the module docs).
    """

    def __init__(
        self,
        env: gym.Env,
        k: int,
        include_latency: bool = False,
        *,
        include_alpha: bool = False,
        include_obs_delay: bool = False,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, k=k, include_latency=include_latency, include_alpha=include_alpha, include_obs_delay=include_obs_delay
        )
        gym.Wrapper.__init__(self, env)
        dtype = _check_spaces(env.observation_space, k, "ActionHistory")
        self.k = int(k)
        self.include_latency = include_latency
        self.include_alpha = include_alpha
        self.include_obs_delay = include_obs_delay
        self._keys = _feature_keys(include_alpha, include_obs_delay, include_latency)
        _check_length(env, self.k, include_alpha, "ActionHistory")
        self._encoder = _ActionEncoder(env.action_space, dtype, "ActionHistory")
        self.observation_space = _augmented_space(env.observation_space, self._encoder, self.k, len(self._keys), dtype)
        self._history = np.zeros((self.k, self._encoder.size), dtype=dtype)
        self._features = np.zeros(len(self._keys), dtype=dtype)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._history[:] = 0
        self._features[:] = [_latency(info.get(key)) for key in self._keys]
        return self._augment(obs), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        features = self._encoder.encode(action, 1)  # before stepping: a bad action changes nothing
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.k:
            self._history[:-1] = self._history[1:]
            self._history[-1] = features[0]
        self._features[:] = [_latency(info.get(key)) for key in self._keys]
        return self._augment(obs), reward, terminated, truncated, info

    @property
    def history(self) -> np.ndarray:
        """A copy of the action features, ``(k, features per action)``, oldest first."""
        return self._history.copy()

    def _augment(self, obs: Any) -> Any:
        parts = [self._history.reshape(-1), self._features]
        if _separate(self.env.observation_space):
            inputs = dict(obs) if isinstance(obs, dict) else {PIXELS_KEY: obs}
            return {**inputs, HISTORY_KEY: np.concatenate(parts)}
        return np.concatenate([np.asarray(obs, dtype=self._history.dtype).reshape(-1), *parts])


def _masked(infos: dict[str, Any], key: str, n: int) -> list[Any]:
    """Per world, ``infos[key]`` where present (Gymnasium's ``_key`` mask), else None."""
    values = infos.get(key)
    if values is None:
        return [None] * n
    mask = infos.get(f"_{key}", np.ones(n, dtype=bool))
    return [values[w] if mask[w] else None for w in range(n)]


class ActionHistoryVector(VectorWrapper, gym.utils.RecordConstructorArgs):
    """:class:`ActionHistory` for a Gymnasium :class:`~gymnasium.vector.VectorEnv`
    (e.g. :class:`remoteenv.RemoteVectorEnv`), one history per world.

    A world's history is zeroed whenever its episode restarts, in every
    autoreset mode (``env.metadata["autoreset_mode"]``, NEXT_STEP if absent):

    - NEXT_STEP: the step after an episode ends resets that world and ignores
      its action, so the action is not recorded and the history starts at zeros.
    - SAME_STEP: the step that ends an episode returns the next episode's first
      observation, with a zero history; ``infos["final_obs"]`` holds the
      ended episode's last observation augmented with its history (including
      the final action) and its features from ``infos["final_info"]``.
    - DISABLED: ``reset(options={"reset_mask": mask})`` zeroes the masked worlds.
    """

    def __init__(
        self,
        env: VectorEnv,
        k: int,
        include_latency: bool = False,
        *,
        include_alpha: bool = False,
        include_obs_delay: bool = False,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, k=k, include_latency=include_latency, include_alpha=include_alpha, include_obs_delay=include_obs_delay
        )
        VectorWrapper.__init__(self, env)
        dtype = _check_spaces(env.single_observation_space, k, "ActionHistoryVector")
        self.k = int(k)
        self.include_latency = include_latency
        self.include_alpha = include_alpha
        self.include_obs_delay = include_obs_delay
        self._keys = _feature_keys(include_alpha, include_obs_delay, include_latency)
        _check_length(env, self.k, include_alpha, "ActionHistoryVector")
        self._encoder = _ActionEncoder(env.single_action_space, dtype, "ActionHistoryVector")
        single = _augmented_space(env.single_observation_space, self._encoder, self.k, len(self._keys), dtype)
        self.single_observation_space = single
        self.observation_space = batch_space(single, self.num_envs)
        self.autoreset_mode = AutoresetMode(env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
        n = self.num_envs
        self._history = np.zeros((n, self.k, self._encoder.size), dtype=dtype)
        self._features = np.zeros((n, len(self._keys)), dtype=dtype)
        self._restarting = np.zeros(n, dtype=bool)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        mask = None if options is None else options.get("reset_mask")  # read before the env pops it
        obs, infos = self.env.reset(seed=seed, options=options)
        worlds = np.ones(self.num_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        self._history[worlds] = 0
        self._restarting[worlds] = False
        for j, key in enumerate(self._keys):
            for w, value in enumerate(_masked(infos, key, self.num_envs)):
                if worlds[w]:
                    self._features[w, j] = _latency(value)
        return self._augment(obs), infos

    def step(self, actions: Any) -> tuple[np.ndarray, Any, Any, Any, dict[str, Any]]:
        n = self.num_envs
        features = self._encoder.encode(actions, n)  # before stepping: a bad action changes nothing
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        recorded = ~self._restarting if self.autoreset_mode == AutoresetMode.NEXT_STEP else np.ones(n, dtype=bool)
        self._history[~recorded] = 0
        if self.k:
            self._history[recorded, :-1] = self._history[recorded, 1:]
            self._history[recorded, -1] = features[recorded]
        for j, key in enumerate(self._keys):
            self._features[:, j] = [_latency(v) for v in _masked(infos, key, n)]
        ended = np.logical_or(terminated, truncated)
        if self.autoreset_mode == AutoresetMode.SAME_STEP and ended.any():
            infos = self._augment_final(infos, ended)
            self._history[ended] = 0
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._restarting = ended.copy()
        return self._augment(obs), rewards, terminated, truncated, infos

    @property
    def history(self) -> np.ndarray:
        """A copy of the action features, ``(num_envs, k, features per action)``, oldest first."""
        return self._history.copy()

    def _augment(self, obs: Any) -> Any:
        n = self.num_envs
        parts = [self._history.reshape(n, -1), self._features]
        if _separate(self.env.single_observation_space):
            inputs = dict(obs) if isinstance(obs, dict) else {PIXELS_KEY: obs}
            return {**inputs, HISTORY_KEY: np.concatenate(parts, axis=1)}
        return np.concatenate([np.asarray(obs, dtype=self._history.dtype).reshape(n, -1), *parts], axis=1)

    def _augment_final(self, infos: dict[str, Any], ended: np.ndarray) -> dict[str, Any]:
        """``infos`` with each ended world's ``final_obs`` augmented (a new dict and array)."""
        final = infos.get("final_obs")
        if final is None:
            return infos
        final = np.array(final, dtype=object, copy=True)
        final_infos = infos.get("final_info") or {}
        columns = [_masked(final_infos, key, self.num_envs) for key in self._keys]
        dtype = self._history.dtype
        separate = _separate(self.env.single_observation_space)
        for w in np.flatnonzero(ended):
            if final[w] is None:
                continue
            parts = [self._history[w].reshape(-1), np.array([_latency(column[w]) for column in columns], dtype=dtype)]
            if separate:
                inputs = dict(final[w]) if isinstance(final[w], dict) else {PIXELS_KEY: final[w]}
                final[w] = {**inputs, HISTORY_KEY: np.concatenate(parts)}
            else:
                final[w] = np.concatenate([np.asarray(final[w], dtype=dtype).reshape(-1), *parts])
        return {**infos, "final_obs": final}
