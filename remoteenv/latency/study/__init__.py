"""The delay-effect study (agent side): PPO trained with and without the
actions in flight, across constant and random action delays.

``python -m remoteenv latency-study`` runs it (see :mod:`remoteenv.cli.latency_study`
and docs/latency.md). :mod:`~remoteenv.latency.study.design` holds the grid
and the learner's settings, :mod:`~remoteenv.latency.study.training` one run,
:mod:`~remoteenv.latency.study.runner` the parallel runs,
:mod:`~remoteenv.latency.study.results` the JSON, table and figure.
"""

from remoteenv.latency.study.design import PPO_SETTINGS, Cell, StudyConfig, cells

__all__ = ["PPO_SETTINGS", "Cell", "StudyConfig", "cells"]
