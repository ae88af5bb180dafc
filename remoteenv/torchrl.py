"""Kept for old imports: the TorchRL adapter live in :mod:`remoteenv.integrations.torchrl` (runs in the agent process)."""

from remoteenv.integrations.torchrl import (
    is_image_space,
    make_torchrl_env,
)

__all__ = ["is_image_space", "make_torchrl_env"]
