"""Kept for old imports: the agent-camera video wrapper lives in :mod:`remoteenv.integrations.camera_video` (runs in the agent process)."""

from remoteenv.integrations.camera_video import RenderObservation, to_rgb

__all__ = ["RenderObservation", "to_rgb"]
