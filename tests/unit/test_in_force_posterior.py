"""The posterior of the action in force from the buffer and alpha, and its
calibration on the lock-step engine (the study's Markov check)."""

from __future__ import annotations

import numpy as np
import pytest

from remoteenv.controllers import CARTPOLE_GAINS, CartpoleExpectedPredictor, CartpolePredictor
from remoteenv.delays import Categorical, Trace, Uniform
from remoteenv.latency.study.markov_check import MODELS, TOLERANCE, calibration, in_force_steps
from remoteenv.wire.delays.in_force import delay_pmf, in_force_posterior, mean_age


@pytest.mark.parametrize("spec", [Uniform(6, 10), Uniform(0, 16), Categorical([2, 5], [0.3, 0.7]), 4])
def test_every_future_tick_has_exactly_one_action_in_force(spec):
    pmf = delay_pmf(spec)
    for alpha in range(len(pmf)):
        buffered, future = in_force_posterior(pmf, alpha, len(pmf) + 2)
        np.testing.assert_allclose(buffered.sum(axis=1) + future.sum(axis=1), 1.0, atol=1e-12)
        assert (buffered >= 0).all() and (future >= 0).all()


def test_under_a_constant_delay_the_posterior_is_certain_and_names_the_actions_in_flight():
    buffered, future = in_force_posterior(delay_pmf(5), alpha=5, horizon=7)
    for h in range(1, 6):  # tick t + h runs the action of age 5 - h
        assert buffered[h - 1, 5 - h] == 1.0
    assert future[5, 0] == 1.0 and future[6, 1] == 1.0  # then the actions sent from now on


def test_a_trace_is_not_iid_and_has_no_posterior():
    with pytest.raises(TypeError):
        delay_pmf(Trace([1, 2, 3]))


@pytest.mark.parametrize("model", MODELS)
def test_the_stationary_mean_age_is_the_engines(model):
    alpha, _ = in_force_steps(model, 20_000, seed=1)
    low, high = (int(v) for v in model[2:-1].split(","))
    assert mean_age(Uniform(low, high)) == pytest.approx(alpha[100:].mean(), abs=0.06)


@pytest.mark.parametrize("model", MODELS)
def test_the_buffer_and_alpha_posterior_is_calibrated_on_the_engine(model):
    result = calibration(model, steps=30_000, seed=3)
    assert result["calibrated"], result["bins"]
    assert result["worst_gap"] <= TOLERANCE and len(result["bins"]) >= 5


def test_the_check_can_fail_a_posterior_that_ignores_what_alpha_says():
    def ignoring_alpha(pmf, alpha, horizon):
        """The newer actions' delays as the model gives them, forgetting that they had not arrived by tick t."""
        cdf = np.cumsum(pmf)
        buffered, future = in_force_posterior(pmf, alpha, horizon)
        for h in range(1, horizon + 1):
            none_newer = 1.0 - future[h - 1].sum()
            for a in range(alpha + 1):
                arrived = 1.0 if a == alpha else float(cdf[min(a + h, len(cdf) - 1)])
                buffered[h - 1, a] = none_newer * arrived
                none_newer *= 1.0 - arrived
        return buffered, future

    assert not calibration("U(6,10)", steps=30_000, seed=3, posterior=ignoring_alpha)["calibrated"]


def test_the_expected_state_predictor_is_the_constant_delay_predictor_when_the_delay_is_known():
    rng = np.random.default_rng(0)
    state = rng.normal(scale=0.05, size=4)
    actions = rng.uniform(-1, 1, size=7)  # a_{t-6} .. a_t; the in-force one has age 6
    expected = CartpoleExpectedPredictor(6, gains=CARTPOLE_GAINS)
    assert expected.horizon == 6
    obs = np.concatenate([state, actions, [6.0]])
    np.testing.assert_allclose(expected(obs), CartpolePredictor()(np.concatenate([state, actions[1:]])))
