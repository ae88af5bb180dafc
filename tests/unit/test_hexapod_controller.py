"""The hexapod's tripod-gait controller as a pure function."""

from __future__ import annotations

import math

import numpy as np
import pytest

from remoteenv import controllers


def _obs_with_yaw(yaw: float) -> np.ndarray:
    obs = np.zeros(67)
    obs[controllers.HEXAPOD_QUAT] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    return obs


def test_action_is_a_valid_box_action_at_any_time():
    obs = _obs_with_yaw(0.0)
    for t in np.linspace(0.0, 2.0, 37):
        action = controllers.hexapod_tripod(obs, float(t))
        assert action.shape == (18,) and action.dtype == np.float32
        assert np.all(np.abs(action) <= 1.0)


def test_tripods_alternate_in_the_air():
    obs = _obs_with_yaw(0.0)
    tripod_a, tripod_b = [0, 2, 4], [1, 3, 5]  # {lf, lr, rm}, {lm, rf, rr}
    for t in np.linspace(0.0, 1.0, 41):
        femur = controllers.hexapod_tripod(obs, float(t)).reshape(6, 3)[:, 1]
        assert not (femur[tripod_a].max() > 1e-6 and femur[tripod_b].max() > 1e-6)
        np.testing.assert_allclose(femur[tripod_a], femur[tripod_a][0])
    period, lift = 0.8, 0.4
    quarter = controllers.hexapod_tripod(obs, period / 4, period=period, lift=lift).reshape(6, 3)
    np.testing.assert_allclose(quarter[tripod_a, 1], lift)
    np.testing.assert_array_equal(quarter[tripod_b, 1], 0.0)
    # The gait repeats every period.
    np.testing.assert_allclose(
        controllers.hexapod_tripod(obs, 0.1, period=period),
        controllers.hexapod_tripod(obs, 0.1 + period, period=period),
        atol=1e-6,
    )


@pytest.mark.parametrize("yaw", [-0.4, 0.0, 0.3, 2.5])
def test_heading_from_the_quaternion(yaw):
    assert controllers.hexapod_heading(_obs_with_yaw(yaw)) == pytest.approx(yaw)


def test_turned_left_shortens_the_right_strides():
    """Yawed counter-clockwise (left), the body must turn right: shorter strides on the right."""
    straight = controllers.hexapod_tripod(_obs_with_yaw(0.0), 0.0).reshape(6, 3)[:, 0]
    turned = controllers.hexapod_tripod(_obs_with_yaw(0.1), 0.0).reshape(6, 3)[:, 0]
    left, right = slice(0, 3), slice(3, 6)
    assert np.all(np.abs(turned[right]) < np.abs(straight[right]))
    assert np.all(np.abs(turned[left]) > np.abs(straight[left]))
