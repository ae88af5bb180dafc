"""Fixed controllers next to the trained policies: the instrument's yardstick.

Agent side. For continuous CartPole the study also evaluates, on the same
evaluation episodes and delays as the trained policies,

- ``LQR`` (:func:`remoteenv.controllers.cartpole_continuous`): delay-unaware,
  on the observation alone, under every delay model of the study;
- ``predictor`` (:class:`remoteenv.controllers.CartpolePredictor`): the same
  gains applied to the state predicted through the ``k`` actions in flight
  (``ActionHistory(env, k)``), under the constant delays, where the history
  holds exactly the actions that will act.

No training: seconds per delay. Other envs (and CartPole observed through
its camera) get no references.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from remoteenv.latency_study.design import StudyConfig
from remoteenv.latency_study.training import evaluate
from remoteenv.wrappers import ActionHistory

CARTPOLE_ID = "remoteenv/CartPole-v0"


def has_references(config: StudyConfig) -> bool:
    """Continuous CartPole observing its state (the controllers read the 4 numbers, not pixels)."""
    return (
        config.env_id == CARTPOLE_ID
        and bool(config.env_kwargs.get("continuous"))
        and config.env_kwargs.get("obs_mode", "state") == "state"
    )


def _mean_return(config: StudyConfig, policy: Any, action_delay: Any, history: int) -> float:
    env: gym.Env = gym.make(config.env_id, action_delay=action_delay, **config.env_kwargs)
    if history:
        env = ActionHistory(env, history)
    try:
        returns = evaluate(env, policy, config.eval_episodes, config.eval_seed)
    finally:
        env.close()
    return float(sum(returns) / len(returns))


def reference_returns(config: StudyConfig) -> dict[str, Any] | None:
    """``{"constant": {name: {delay: mean return}}, "uniform": {...}}`` for the
    study's delays (JSON keys are strings), or None for envs without references."""
    if not has_references(config):
        return None
    from remoteenv.controllers import CartpolePredictor, cartpole_continuous
    from remoteenv.delays import Uniform

    predictor = CartpolePredictor()
    constant: dict[str, dict[str, float]] = {"LQR (delay-unaware)": {}, "predictor (model + actions in flight)": {}}
    for k in config.delays:
        constant["LQR (delay-unaware)"][str(k)] = _mean_return(config, cartpole_continuous, k, 0)
        constant["predictor (model + actions in flight)"][str(k)] = _mean_return(config, predictor, k, k)
    uniform: dict[str, dict[str, float]] = {"LQR (delay-unaware)": {}}
    for k in config.random_delays:
        uniform["LQR (delay-unaware)"][str(k)] = _mean_return(config, cartpole_continuous, Uniform(0, k), 0)
    return {"constant": constant, "uniform": uniform}
