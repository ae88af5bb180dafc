"""Sims on a Ray cluster: ``RayLauncher`` places an env's sim processes on the
cluster's nodes (``pip install "remoteenv[ray]"``; see docs/cluster.md).

Agent side: imports :mod:`remoteenv.agent` and :mod:`remoteenv.wire`, never
:mod:`remoteenv.sim` (the sims run as separate processes on the nodes).
"""

from remoteenv.integrations.ray.placement import STRATEGIES
from remoteenv.integrations.ray.ray_launcher import RayLauncher

__all__ = ["STRATEGIES", "RayLauncher"]
