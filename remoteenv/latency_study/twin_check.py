"""Kept for old imports: this path is :mod:`remoteenv.latency.study.twin_check` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import twin_check

sys.modules[__name__] = twin_check
