"""Kept for old imports: the Stable-Baselines3 adapters live in :mod:`remoteenv.integrations.sb3` (runs in the agent process)."""

from remoteenv.integrations.sb3 import (
    SB3VecEnv,
    make_sb3_vec_env,
    split_infos,
)

__all__ = ["SB3VecEnv", "make_sb3_vec_env", "split_infos"]
