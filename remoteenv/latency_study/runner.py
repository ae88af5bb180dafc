"""Kept for old imports: this path is :mod:`remoteenv.latency.study.runner` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import runner

sys.modules[__name__] = runner
