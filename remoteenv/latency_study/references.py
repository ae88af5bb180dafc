"""Kept for old imports: this path is :mod:`remoteenv.latency.study.references` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import references

sys.modules[__name__] = references
