"""Which CPU each of a vector env's own lock-step sims is pinned to: one each,
in the agent's CPU order, only when at least two fit and each steps on one
thread; and the ``place_sims`` values accepted."""

from __future__ import annotations

import pytest

from remoteenv.agent.vector.sim_placement import SimPlacement, check_place_sims, placement


def test_sims_that_fit_get_one_cpu_each_in_order():
    assert placement([11, 12], [3, 1, 2], one_thread=True) == [1, 2]
    assert placement([11, 12, 13], [0, 1, 2], one_thread=True) == [0, 1, 2]


def test_no_pinning_for_one_sim_more_sims_than_cpus_or_threaded_physics():
    assert placement([11], [0, 1], one_thread=True) == [None]
    assert placement([11, 12, 13], [0, 1], one_thread=True) == [None, None, None]
    assert placement([11, 12], [0, 1], one_thread=False) == [None, None]


def test_place_sims_values():
    assert check_place_sims("auto") == "auto" and check_place_sims(None) is None
    for bad in ("yes", True, 1, "AUTO"):
        with pytest.raises(ValueError, match="place_sims"):
            check_place_sims(bad)


def test_inactive_in_real_time_for_foreign_sims_and_when_asked_not_to():
    assert SimPlacement("auto", own_sims=True, real_time=False).active
    assert not SimPlacement("auto", own_sims=True, real_time=True).active
    assert not SimPlacement("auto", own_sims=False, real_time=False).active
    assert not SimPlacement(None, own_sims=True, real_time=False).active
