"""A delay-aware reference controller: the latency instrument's self-check.

Continuous CartPole, lock-step, every action taking effect a constant
``k`` control ticks (20 ms each) after it was sent (``action_delay=k``).
Two fixed controllers, no training:

- ``lqr``: the shipped LQR (``remoteenv.controllers.cartpole_continuous``)
  on the delayed observation. It does not know about the delay.
- ``predictor``: ``remoteenv.controllers.CartpolePredictor``. It takes the
  ``k`` actions still in flight from ``ActionHistory(env, k)``, rolls a
  MuJoCo copy of the scene's model forward through them from the delayed
  observation, and applies the same LQR gains to the predicted state.

If the delays land where docs/delays.md says they do, and the history
holds exactly the actions in flight, the predictor balances for the full
500 steps at every delay where the first action can still arrive before the
pole falls (on this scene: every k up to 16 and beyond), while the plain LQR
holds up to 4 ticks and falls soon after from 5 or 6. Lock-step is exact, so
every number below repeats bit for bit.

Run:  python examples/delay_aware_controller.py                 (~20 s)
      python examples/delay_aware_controller.py --delays 0,8 --seeds 0 --json out.json
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import remoteenv  # noqa: F401  (registers remoteenv/CartPole-v0)
from remoteenv.controllers import CARTPOLE_OBS, CartpolePredictor, cartpole_continuous
from remoteenv.latency.action_history import ActionHistory

ENV_ID = "remoteenv/CartPole-v0"
DEFAULT_DELAYS = (0, 2, 4, 5, 6, 8, 10, 12, 14, 16)
MAX_STEPS = 500


def lqr(obs: np.ndarray) -> np.ndarray:
    """The plain LQR on the (delayed) observation; the action history is ignored."""
    return cartpole_continuous(obs[:CARTPOLE_OBS])


def episode_return(env: gym.Env, policy: Callable[[np.ndarray], Any], seed: int) -> float:
    """One episode from ``reset(seed=seed)``: the sum of its rewards (one per tick balanced)."""
    obs, _ = env.reset(seed=seed)
    total, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        total += float(reward)
        done = terminated or truncated
    return total


def sweep(delays: Sequence[int], seeds: Sequence[int], max_steps: int = MAX_STEPS) -> list[dict[str, Any]]:
    """Every (controller, delay, seed): one episode each, in lock-step.

    Returns records ``{"controller", "delay", "seed", "return"}``."""
    controllers = {"lqr": lqr, "predictor": CartpolePredictor()}
    records = []
    for k in delays:
        env = ActionHistory(gym.make(ENV_ID, continuous=True, action_delay=k, max_episode_steps=max_steps), k)
        try:
            for name, policy in controllers.items():
                for seed in seeds:
                    ret = episode_return(env, policy, seed)
                    records.append({"controller": name, "delay": k, "seed": seed, "return": ret})
        finally:
            env.close()
    return records


def table(records: list[dict[str, Any]]) -> str:
    """Mean return (and the seeds' range) per controller and delay, as a text table."""
    delays = sorted({r["delay"] for r in records})
    lines = ["delay (ticks) " + "".join(f"{k:>13}" for k in delays)]
    for name in ("lqr", "predictor"):
        cells = []
        for k in delays:
            returns = [r["return"] for r in records if r["controller"] == name and r["delay"] == k]
            cells.append(f"{np.mean(returns):5.0f} ({min(returns):.0f}-{max(returns):.0f})")
        lines.append(f"{name:<14}" + "".join(f"{c:>13}" for c in cells))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--delays", default=",".join(map(str, DEFAULT_DELAYS)), help="action delays (ticks)")
    parser.add_argument("--seeds", default="0,1,2", help="reset seeds, one episode each")
    parser.add_argument("--max-steps", type=int, default=MAX_STEPS, help="steps per episode at most")
    parser.add_argument("--json", default=None, help="also write every record to this JSON file")
    args = parser.parse_args(argv)
    delays = [int(k) for k in args.delays.split(",")]
    seeds = [int(s) for s in args.seeds.split(",")]
    records = sweep(delays, seeds, args.max_steps)
    print(f"Return of {args.max_steps} at most, mean over seeds {seeds} (their range):")
    print(table(records))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"env": ENV_ID, "max_steps": args.max_steps, "records": records}, f, indent=1)
    return records


if __name__ == "__main__":
    main()
