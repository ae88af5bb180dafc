"""Kept for old imports: Ray placement's names live in :mod:`remoteenv.integrations.ray` (runs in the agent process)."""

from remoteenv.integrations.ray import (
    STRATEGIES,
    RayLauncher,
)

__all__ = ["RayLauncher", "STRATEGIES"]
