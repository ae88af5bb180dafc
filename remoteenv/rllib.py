"""Kept for old imports: the RLlib helpers live in :mod:`remoteenv.integrations.rllib` (runs in the agent process)."""

from remoteenv.integrations.rllib import (
    EnvCreator,
    register_envs,
)

__all__ = ["EnvCreator", "register_envs"]
