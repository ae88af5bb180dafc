"""Kept for old imports: this path is :mod:`remoteenv.latency.study.training` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import training

sys.modules[__name__] = training
