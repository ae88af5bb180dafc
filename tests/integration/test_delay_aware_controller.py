"""The delay-aware reference controller and its example: the predictor sees
the future the sim will produce, and holds where the plain LQR falls."""

from __future__ import annotations

import importlib.util
import json
import os

import gymnasium as gym
import numpy as np

import remoteenv  # noqa: F401
from remoteenv.controllers import CartpoleHoldPredictor, CartpolePredictor, cartpole_continuous

EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "delay_aware_controller.py")


def _example():
    spec = importlib.util.spec_from_file_location("delay_aware_controller", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_prediction_is_the_sims_own_future():
    """From x_t through the next actions the copy of the model lands where the sim does."""
    env = gym.make("remoteenv/CartPole-v0", continuous=True)
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, size=1).astype(np.float32) for _ in range(6)]
    try:
        obs = [env.reset(seed=4)[0]]
        for a in actions:
            obs.append(env.step(a)[0])
    finally:
        env.close()
    predictor = CartpolePredictor()
    for k in (0, 1, 3, 6):
        np.testing.assert_allclose(predictor.predict(obs[0], actions[:k]), obs[k], atol=1e-5)
    np.testing.assert_array_equal(predictor(obs[2]), cartpole_continuous(obs[2]))  # nothing in flight
    history_obs = np.concatenate([obs[0], np.concatenate(actions[:3])])  # ActionHistory(env, 3)'s layout
    np.testing.assert_array_equal(predictor(history_obs), cartpole_continuous(predictor.predict(obs[0], actions[:3])))
    held = CartpoleHoldPredictor(2, predictor)
    first = held(obs[1])  # the previous action is the default one, zero force
    np.testing.assert_array_equal(first, cartpole_continuous(predictor.predict(obs[1], [np.zeros(1)] * 2)))
    np.testing.assert_array_equal(held(obs[2]), cartpole_continuous(predictor.predict(obs[2], [first] * 2)))


def test_the_example_holds_where_the_plain_lqr_falls(tmp_path, capsys):
    """At 8 ticks of action delay the plain LQR falls and the predictor holds
    all 500 steps; lock-step is exact, so this is the same on every run."""
    out = tmp_path / "sweep.json"
    _example().main(["--delays", "0,8", "--seeds", "0", "--json", str(out)])
    returns = {(r["controller"], r["delay"]): r["return"] for r in json.loads(out.read_text())["records"]}
    assert returns[("lqr", 0)] == returns[("predictor", 0)] == 500.0
    assert returns[("predictor", 8)] == 500.0
    assert returns[("lqr", 8)] < 100.0
    assert "predictor" in capsys.readouterr().out


def test_the_expected_state_predictor_holds_under_jitter_where_the_plain_lqr_falls():
    """Uniform(8, 16): from the buffer and alpha alone (what a history + alpha policy
    sees), the expected in-force actions are enough to balance; the LQR is not."""
    from remoteenv.controllers import CartpoleExpectedPredictor
    from remoteenv.delays import Uniform
    from remoteenv.latency.action_history import ActionHistory
    from remoteenv.latency.study.training import evaluate

    spec = Uniform(8, 16)
    env = gym.make("remoteenv/CartPole-v0", continuous=True, action_delay=spec, max_episode_steps=300)
    try:
        lqr = evaluate(env, cartpole_continuous, 2, 10_000)
    finally:
        env.close()
    env = ActionHistory(
        gym.make("remoteenv/CartPole-v0", continuous=True, action_delay=spec, max_episode_steps=300),
        17,
        include_alpha=True,
    )
    try:
        expected = evaluate(env, CartpoleExpectedPredictor(spec), 2, 10_000)
    finally:
        env.close()
    assert max(lqr) < 150
    assert expected == [300.0, 300.0]
