"""Kept for old imports: the delay-effect study's names (and its submodules, each under its old name too) live in :mod:`remoteenv.latency.study` (runs in the agent process)."""

from remoteenv.latency.study import (
    PPO_SETTINGS,
    Cell,
    StudyConfig,
    cells,
)

__all__ = ["Cell", "PPO_SETTINGS", "StudyConfig", "cells"]
