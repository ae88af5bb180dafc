"""Which observation and action spaces the delay-effect study trains on, and with which policy.

Agent side. The study trains Stable-Baselines3 PPO, and its ``history``
variant adds the actions in flight with :class:`remoteenv.latency.action_history.ActionHistory`
(beside an image or a Dict as a separate ``"history"`` input). So:

- observations: a Box of values (``MlpPolicy``), an image (uint8 ``H x W x C``
  of at least :data:`MIN_IMAGE_SIDE` pixels a side: ``CnnPolicy``, or
  ``MultiInputPolicy`` once the history is beside it), or a flat Dict of
  Boxes, Discretes, MultiBinaries and MultiDiscretes without a ``"history"``
  key (``MultiInputPolicy``);
- actions: Box or Discrete.

:func:`check_spaces` refuses anything else with what to change, and
:func:`probe_spaces` reads an id's spaces (one env made and closed) so the
command can refuse before the study starts any of its sims.

Runs in the agent process.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from gymnasium import spaces

from remoteenv.latency.action_history import HISTORY_KEY, is_image

#: The smallest image side SB3's default CNN (NatureCNN) takes.
MIN_IMAGE_SIDE = 36
_DICT_ENTRIES = (spaces.Box, spaces.Discrete, spaces.MultiBinary, spaces.MultiDiscrete)


def policy_for(space: spaces.Space) -> str:
    """SB3's policy for an observation space (after any wrapper): multi-input for
    a Dict, CNN for an image, MLP otherwise."""
    if isinstance(space, spaces.Dict):
        return "MultiInputPolicy"
    if is_image(space):
        return "CnnPolicy"
    return "MlpPolicy"


def _image_problem(space: spaces.Space, where: str) -> str | None:
    shape = space.shape or ()
    if is_image(space) and min(shape[:2]) < MIN_IMAGE_SIDE:
        return (
            f"{where} is an image of {shape[0]}x{shape[1]} pixels, smaller than the "
            f"{MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE} SB3's CNN takes; render larger images "
            '(e.g. --env-kwargs \'{"obs_mode": "pixels", "image_size": 64}\')'
        )
    return None


def space_problem(observation_space: spaces.Space, action_space: spaces.Space) -> str | None:
    """Why the study cannot train on these spaces (None if it can), with the fix."""
    if not isinstance(action_space, (spaces.Box, spaces.Discrete)):
        return (
            f"actions of {action_space}: the study's action history encodes Box and Discrete actions only; "
            "give the scene a Box or Discrete action space"
        )
    if isinstance(observation_space, spaces.Dict):
        odd = [k for k, s in observation_space.spaces.items() if not isinstance(s, _DICT_ENTRIES)]
        if odd:
            return (
                f"the Dict observation's entries {odd} are nested Dicts, Tuples or other spaces SB3's "
                "MultiInputPolicy cannot take; flatten them into Boxes in the scene"
            )
        if HISTORY_KEY in observation_space.spaces:
            return (
                f"the Dict observation has a {HISTORY_KEY!r} key, where the study puts the actions in flight; "
                "rename that entry in the scene"
            )
        for key, sub in observation_space.spaces.items():
            problem = _image_problem(sub, f"the Dict observation's {key!r}")
            if problem:
                return problem
        return None
    if isinstance(observation_space, spaces.Box):
        return _image_problem(observation_space, "the observation")
    return (
        f"observations of {observation_space}: the study trains on a Box (values or an image) or a flat Dict; "
        "give the scene such an observation space (e.g. a camera obs_mode, or flatten it)"
    )


def check_spaces(env_id: str, observation_space: spaces.Space, action_space: spaces.Space) -> None:
    """Raise ``ValueError`` naming ``env_id``, the space and the fix unless the study can train on it."""
    problem = space_problem(observation_space, action_space)
    if problem is not None:
        raise ValueError(f"latency-study cannot train on {env_id}: {problem}")


def probe_spaces(env_id: str, env_kwargs: dict[str, Any]) -> tuple[spaces.Space, spaces.Space]:
    """``(observation_space, action_space)`` of ``env_id`` made with ``env_kwargs``
    (one env made, its handshake read, closed at once)."""
    env = gym.make(env_id, **env_kwargs)
    try:
        return env.observation_space, env.action_space
    finally:
        env.close()


__all__ = ["MIN_IMAGE_SIDE", "check_spaces", "policy_for", "probe_spaces", "space_problem"]
