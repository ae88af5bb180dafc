"""LatencyStats' delayed lock-step figures: the age of the action in force and the actions that never acted."""

from __future__ import annotations

import numpy as np
import pytest

from remoteenv.agent.session.latency_stats import LatencyStats
from remoteenv.delays import Uniform
from remoteenv.wire.delays.delay_line import LockStepDelays


def test_single_env_stats_equal_the_engines_own_counts():
    engine = LockStepDelays(Uniform(0, 6), Uniform(0, 2))
    stats = LatencyStats()
    engine.reset(0, 0.0, None, seed=4)
    for t in range(1, 2001):
        engine.apply(t)
        _, record = engine.observe(t, 0.0)
        info = record.info()
        info["latency_s"] = None if info["latency_ticks"] is None else info["latency_ticks"] * 0.02
        stats.record(info)
    own = engine.stats()
    assert stats.actions_sent == own["actions_sent"] == 2000
    assert stats.actions_acted == own["actions_acted"]
    assert stats.never_acted_fraction == pytest.approx(own["never_acted_fraction"])
    assert stats.action_age_ticks.mean == pytest.approx(own["mean_action_age_ticks"])
    assert stats.never_applied == 0  # a default acting is not an action lost (that is real time's count)
    summary = stats.summary()
    assert summary["actions_sent"] == 2000 and "never acted" in stats.format()


def test_vector_stats_count_each_world_and_skip_worlds_without_the_keys():
    stats = LatencyStats()
    ages = np.array([1, 0, 0], dtype=np.int64)
    took = np.array([False, True, False])
    infos = {
        "action_delay_ticks": ages,
        "_action_delay_ticks": np.array([True, True, False]),
        "action_took_effect": took,
        "_action_took_effect": np.array([True, True, False]),
        "latency_s": np.array([None, 0.0, None], dtype=object),
        "_latency_s": np.array([True, True, False]),
    }
    stats.record_vector(infos)
    assert stats.actions_sent == 2 and stats.actions_acted == 1 and stats.never_acted_fraction == 0.5
    assert stats.action_age_ticks.mean == 0.5 and stats.never_applied == 0
    stats.reset()
    assert stats.actions_sent == 0 and stats.never_acted_fraction is None
