"""Kept for old imports: this path is :mod:`remoteenv.latency.study.resumed` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import resumed

sys.modules[__name__] = resumed
