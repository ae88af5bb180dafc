"""Kept for old imports: the TorchRL adapter live in :mod:`remoteenv.integrations.torchrl` (runs in the agent process)."""

from remoteenv.integrations.torchrl import (
    make_torchrl_env,
)

__all__ = ["make_torchrl_env"]
