"""Fixed controllers next to the trained policies: the instrument's yardstick.

Agent side. For continuous CartPole the study also evaluates, on the same
evaluation episodes and delays as the trained policies,

- ``LQR`` (:func:`remoteenv.scene_controllers.cartpole.cartpole_continuous`): delay-unaware,
  on the observation alone, under every delay model of the study;
- ``predictor`` (:class:`remoteenv.latency.predictors.CartpolePredictor`): the same
  gains applied to the state predicted through the ``k`` actions in flight
  (``ActionHistory(env, k)``), under the constant delays, where the history
  holds exactly the actions that will act;
- ``expected-state predictor`` (:class:`remoteenv.latency.predictors.CartpoleExpectedPredictor`)
  under each random model: it sees what the history + alpha policy sees
  (``ActionHistory(env, high + 1, include_alpha=True)``), rolls the model
  through the expected actions in force (their posterior given the buffer
  and alpha) for the stationary mean age of the action in force, and applies
  :data:`remoteenv.scene_controllers.cartpole.CARTPOLE_SOFT_GAINS` (the same for every
  model): what the information the policy has allows.

No training: seconds per delay. Other envs (and CartPole observed through
its camera) get no references.

Runs in the agent process.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from remoteenv.latency.action_history import ActionHistory
from remoteenv.latency.study.design import StudyConfig, random_model
from remoteenv.latency.study.training import evaluate
from remoteenv.wire.delays.channel_rules import NEWEST

CARTPOLE_ID = "remoteenv/CartPole-v0"


def has_references(config: StudyConfig) -> bool:
    """Continuous CartPole observing its state (the controllers read the 4 numbers, not pixels)."""
    return (
        config.env_id == CARTPOLE_ID
        and bool(config.env_kwargs.get("continuous"))
        and config.env_kwargs.get("obs_mode", "state") == "state"
    )


#: Names of the reference controllers (the delay-unaware one's contains "LQR").
LQR = "LQR (delay-unaware)"
PREDICTOR = "predictor (model + actions in flight)"
EXPECTED = "expected-state predictor (buffer + alpha)"


def _mean_return(config: StudyConfig, policy: Any, action_delay: Any, history: int, alpha: bool = False) -> float:
    env: gym.Env = gym.make(config.env_id, action_delay=action_delay, **config.env_kwargs)
    if history:
        env = ActionHistory(env, history, include_alpha=alpha)
    try:
        check = getattr(policy, "check_env", None)
        if callable(check):  # refuses, in one line, an env it does not predict
            check(env)
        returns = evaluate(env, policy, config.eval_episodes, config.eval_seed)
    finally:
        env.close()
    return float(sum(returns) / len(returns))


def reference_returns(config: StudyConfig) -> dict[str, Any] | None:
    """``{"constant": {name: {delay: mean return}}, "random": {...}, "gains":
    {name: gains}}`` for the study's delays (JSON keys are strings: ``"8"``,
    ``"U(6,10)"``), or None for envs without references."""
    if not has_references(config):
        return None
    from remoteenv.latency.predictors import CartpoleExpectedPredictor, CartpolePredictor
    from remoteenv.scene_controllers.cartpole import CARTPOLE_GAINS, CARTPOLE_SOFT_GAINS, cartpole_continuous

    predictor = CartpolePredictor()
    constant: dict[str, dict[str, float]] = {LQR: {}, PREDICTOR: {}}
    for k in config.delays:
        constant[LQR][str(k)] = _mean_return(config, cartpole_continuous, k, 0)
        constant[PREDICTOR][str(k)] = _mean_return(config, predictor, k, k)
    random: dict[str, dict[str, float]] = {LQR: {}, EXPECTED: {}}
    for name in config.random_delays:
        spec = random_model(name)
        random[LQR][name] = _mean_return(config, cartpole_continuous, spec, 0)
        expected = CartpoleExpectedPredictor(spec, action_delivery=config.env_kwargs.get("action_delivery", NEWEST))
        random[EXPECTED][name] = _mean_return(config, expected, spec, int(spec.high) + 1, alpha=True)
    gains = {LQR: CARTPOLE_GAINS.tolist(), PREDICTOR: CARTPOLE_GAINS.tolist(), EXPECTED: CARTPOLE_SOFT_GAINS.tolist()}
    return {"constant": constant, "random": random, "gains": gains}
