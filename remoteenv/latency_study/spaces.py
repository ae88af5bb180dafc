"""Kept for old imports: this path is :mod:`remoteenv.latency.study.trainable_spaces` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import trainable_spaces

sys.modules[__name__] = trainable_spaces
