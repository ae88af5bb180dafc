"""Kept for old imports: the RLlib helpers live in :mod:`remoteenv.integrations.rllib` (runs in the agent process)."""

from remoteenv.integrations.rllib import (
    EnvCreator,
    float_image_space,
    is_uint8_image,
    register_envs,
    scale_images,
)

__all__ = ["EnvCreator", "float_image_space", "is_uint8_image", "register_envs", "scale_images"]
