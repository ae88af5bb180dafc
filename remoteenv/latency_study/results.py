"""Kept for old imports: this path is :mod:`remoteenv.latency.study.results` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import results

sys.modules[__name__] = results
