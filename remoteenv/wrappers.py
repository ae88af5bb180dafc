"""Kept for old imports: the delay-aware observation wrappers live in :mod:`remoteenv.latency.action_history` (runs in the agent process)."""

from remoteenv.latency.action_history import (
    HISTORY_KEY,
    PIXELS_KEY,
    ActionHistory,
    ActionHistoryVector,
    is_image,
    required_history,
)

__all__ = ["ActionHistory", "ActionHistoryVector", "HISTORY_KEY", "PIXELS_KEY", "is_image", "required_history"]
