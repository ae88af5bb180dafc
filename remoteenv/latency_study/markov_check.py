"""Kept for old imports: this path is :mod:`remoteenv.latency.study.markov_check` itself, the same module
object (runs in the agent process)."""

import sys

from remoteenv.latency.study import markov_check

if __name__ == "__main__":
    raise SystemExit(markov_check.main())

sys.modules[__name__] = markov_check
