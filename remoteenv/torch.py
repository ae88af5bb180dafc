"""Kept for old imports: the frame streaming into a torch ``DataLoader`` live in :mod:`remoteenv.integrations.frame_dataset` (runs in the agent process)."""

from remoteenv.integrations.frame_dataset import (
    Publishers,
    RemoteIterableDataset,
    launch_publishers,
)

__all__ = ["Publishers", "RemoteIterableDataset", "launch_publishers"]
