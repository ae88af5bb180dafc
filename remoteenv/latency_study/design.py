"""Kept for old imports: this path is :mod:`remoteenv.latency.study.design` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import design

sys.modules[__name__] = design
