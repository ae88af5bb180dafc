"""The posterior of the action in force from the buffer and alpha, and its
calibration on the lock-step engine (the study's Markov check)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from remoteenv.controllers import CARTPOLE_GAINS, CartpoleExpectedPredictor, CartpolePredictor
from remoteenv.delays import Categorical, Trace, Uniform
from remoteenv.latency.study.markov_check import MODELS, TOLERANCE, calibration, in_force_steps
from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.in_force import delay_pmf, in_force_posterior, mean_age
from remoteenv.wrappers import ActionHistory


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


# ---------------------------------------------------------------------------
# Both delivery rules, with and without an observation delay.

RULES = ("newest", "in_order")
OBS_MODELS = (None, "U(0,4)")


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("obs_age", [0, 3])
@pytest.mark.parametrize("from_obs", [False, True])
def test_every_tick_has_exactly_one_action_in_force_under_both_rules(rule, obs_age, from_obs):
    pmf = delay_pmf(Uniform(2, 9))
    for alpha in range(len(pmf)):
        buffered, future = in_force_posterior(pmf, alpha, 11, obs_age=obs_age, rule=rule, from_obs=from_obs)
        assert buffered.shape == ((obs_age if from_obs else 0) + 11, alpha + obs_age + 1)
        np.testing.assert_allclose(buffered.sum(axis=1) + future.sum(axis=1), 1.0, atol=1e-12)
        assert (buffered >= -1e-15).all() and (future >= -1e-15).all()


@pytest.mark.parametrize("rule", RULES)
def test_under_constant_delays_both_rules_name_the_actions_in_flight_from_the_observation(rule):
    # Action delay 5, the observation 2 ticks old: tick t + h (h from -1) runs the action of age 5 - h.
    buffered, future = in_force_posterior(delay_pmf(5), alpha=5, horizon=7, obs_age=2, rule=rule, from_obs=True)
    for row, h in enumerate(range(-1, 8)):
        if h <= 5:
            assert buffered[row, 5 - h] == 1.0
        else:
            assert future[row, h - 6] == 1.0


@pytest.mark.parametrize("rule", RULES)
def test_the_stationary_mean_age_follows_the_rule(rule):
    from remoteenv.latency_study.markov_check import engine_steps

    alpha, _, _ = engine_steps("U(0,16)", 30_000, 1, None, rule)
    assert mean_age(Uniform(0, 16), rule) == pytest.approx(alpha[100:].mean(), abs=0.15)
    assert mean_age(Uniform(0, 16), "in_order") > 3 * mean_age(Uniform(0, 16), "newest")


@pytest.mark.parametrize("model", ["U(6,10)", "U(0,16)"])
@pytest.mark.parametrize("obs_model", OBS_MODELS, ids=["no obs delay", "obs U(0,4)"])
@pytest.mark.parametrize("rule", RULES)
def test_the_posterior_is_calibrated_under_each_rule_and_observation_delay(rule, obs_model, model):
    result = calibration(model, steps=150_000, seed=3, obs_model=obs_model, rule=rule)
    assert result["calibrated"], result["bins"]
    assert result["worst_gap"] <= TOLERANCE and sum(b["judged"] for b in result["bins"]) >= 5


def wrong_rule(pmf, alpha, horizon, obs_age=0, rule="newest"):
    """The other delivery rule's posterior."""
    return in_force_posterior(pmf, alpha, horizon, obs_age=obs_age, rule="in_order" if rule == "newest" else "newest")


def ignoring_omega(pmf, alpha, horizon, obs_age=0, rule="newest"):
    """The posterior as if the observation were fresh (the former newest-only one, under newest)."""
    return in_force_posterior(pmf, alpha, horizon, rule=rule)


@pytest.mark.parametrize("obs_model", OBS_MODELS, ids=["no obs delay", "obs U(0,4)"])
@pytest.mark.parametrize("rule", RULES)
def test_the_check_fails_a_posterior_of_the_wrong_rule_or_one_ignoring_omega(rule, obs_model):
    assert not calibration("U(6,10)", steps=30_000, seed=3, posterior=wrong_rule, obs_model=obs_model, rule=rule)[
        "calibrated"
    ]
    if obs_model is not None:
        control = calibration("U(6,10)", steps=30_000, seed=3, posterior=ignoring_omega, obs_model=obs_model, rule=rule)
        assert not control["calibrated"]


def test_the_expected_state_predictor_rolls_from_the_delayed_observation():
    rng = np.random.default_rng(1)
    state = rng.normal(scale=0.05, size=4)
    actions = rng.uniform(-1, 1, size=9)  # a_{t-8} .. a_t; alpha 6 at the observation's tick, omega 2
    expected = CartpoleExpectedPredictor(6, gains=CARTPOLE_GAINS, obs_delay=2)
    obs = np.concatenate([state, actions, [6.0, 2.0]])
    # Ticks m + 1 .. t + 6 run the actions of ages 7 .. 0.
    np.testing.assert_allclose(expected(obs), CartpolePredictor()(np.concatenate([state, actions[1:]])))


class DelayedStandIn(gym.Env):
    """A lock-step env's handshake and spaces, without a sim."""

    observation_space = gym.spaces.Box(-10, 10, (4,))
    action_space = gym.spaces.Box(-1, 1, (1,))

    def __init__(self, stepping: dict) -> None:
        self.handshake = {"stepping": stepping}


def stand_in(k=17, alpha=True, omega=False, latency=False, **stepping):
    env = DelayedStandIn({"mode": "lock_step", "action_delay": 16, **stepping})
    return ActionHistory(env, k, latency, include_alpha=alpha, include_obs_delay=omega)


def test_the_expected_state_predictor_is_built_for_an_env_and_refuses_what_it_cannot_predict_in_one_line():
    u = Uniform(8, 16).to_wire()
    in_order = ChannelRules(action_delivery="in_order").to_wire()
    obs = Uniform(0, 4).to_wire()
    built = CartpoleExpectedPredictor.for_env(stand_in(action_delay_spec=u, channel=in_order))
    assert (
        built.rule == "in_order"
        and not built.with_omega
        and built.horizon == round(mean_age(Uniform(8, 16), "in_order"))
    )
    built = CartpoleExpectedPredictor.for_env(stand_in(21, omega=True, action_delay_spec=u, obs_delay_spec=obs))
    assert built.rule == "newest" and built.with_omega
    predictor = CartpoleExpectedPredictor(Uniform(8, 16))
    refusals = [
        (DelayedStandIn({"mode": "real_time"}), "runs in real time"),
        (stand_in(action_delay_spec=Uniform(6, 10).to_wire()), "action delay is Uniform\\(6, 10"),
        (stand_in(action_delay_spec=u, channel=in_order), "delivers actions 'in_order'"),
        (stand_in(21, omega=True, action_delay_spec=u, obs_delay_spec=obs), "observation delay is Uniform\\(0, 4"),
        (stand_in(action_delay_spec=u, alpha=False), "needs ActionHistory"),
        (stand_in(action_delay_spec=u, latency=True), "without include_latency"),
        (stand_in(k=9, action_delay_spec=u), "k>=17"),
    ]
    for env, message in refusals:
        with pytest.raises(ValueError, match=message) as err:
            predictor.check_env(env)
        assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="include_obs_delay must be True"):
        CartpoleExpectedPredictor.for_env(stand_in(21, action_delay_spec=u, obs_delay_spec=obs))
    with pytest.raises(ValueError, match="cannot predict this env's delays"):
        CartpoleExpectedPredictor.for_env(stand_in(action_delay_spec=Trace([1, 2, 3]).to_wire()))
