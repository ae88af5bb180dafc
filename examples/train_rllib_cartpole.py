"""Train RLlib PPO (new API stack) on remoteenv/CartPole-v0, or any registered remote env id.

RLlib's env runners are separate processes that never import remoteenv, so
a plain id (``"remoteenv/CartPole-v0"``) is unknown there. One call in the
driver registers every remote env id with Ray Tune's env registry, which
RLlib's runners read::

    import remoteenv.integrations.rllib
    remoteenv.integrations.rllib.register_envs()
    config.environment("remoteenv/CartPole-v0")

Each env runner builds its envs with ``gym.make_vec``; with
``gym_env_vectorize_mode="vector_entry_point"`` that is one
``RemoteVectorEnv`` per runner, whose worlds share one sim process and step
from one request. Keyword arguments of the env go in ``env_config``.

    python examples/train_rllib_cartpole.py                  # until mean return >= 450
    python examples/train_rllib_cartpole.py --env my_arm:my_arm/MyArm-v0 --target=-inf --iterations 5

Needs ``pip install torch==2.13.0 "ray[rllib]==2.60.0"`` (torch first). Exits
1 if the return is not reached within ``--iterations``. Measured on the
2-core reference machine: see docs/cluster.md, "RLlib". The RLlib settings
are RLlib's for CartPole; another env may want others.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

ENV_ID = "remoteenv/CartPole-v0"
TARGET_RETURN = 450.0


def make_config(env_runners: int, envs_per_runner: int, seed: int, env_id: str = ENV_ID) -> Any:
    """PPO on ``env_id`` (a plain id: see :func:`register`), with RLlib's settings for CartPole."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    return (
        PPOConfig()
        .environment(env_id, env_config={"seed": seed})
        .env_runners(
            num_env_runners=env_runners,
            num_envs_per_env_runner=envs_per_runner,
            gym_env_vectorize_mode="vector_entry_point",
        )
        .training(lr=3e-4, num_epochs=6, vf_loss_coeff=0.01, train_batch_size_per_learner=4000)
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=[32], fcnet_activation="linear", vf_share_layers=True))
        .debugging(seed=seed)
    )


def register(env_id: str = ENV_ID) -> str:
    """Make ``env_id`` known to RLlib's env runners; returns the plain id to configure.
    ``"module:id"`` imports ``module`` first (an env package of your own)."""
    import remoteenv.integrations.rllib

    return remoteenv.integrations.rllib.register_envs(env_id)[0]


def train(
    iterations: int,
    target: float = TARGET_RETURN,
    env_runners: int = 1,
    envs_per_runner: int = 4,
    seed: int = 0,
    log: Any = print,
    env_id: str = ENV_ID,
) -> list[dict[str, float]]:
    """Train until the mean episode return reaches ``target`` or ``iterations`` are done.

    Connects to the Ray cluster this process is attached to (``ray.init``
    first), else starts a local one. Returns one row per iteration:
    ``{"iteration", "return_mean", "env_steps", "seconds"}``."""
    algo = make_config(env_runners, envs_per_runner, seed, register(env_id)).build_algo()
    rows: list[dict[str, float]] = []
    start = time.perf_counter()
    try:
        for i in range(1, iterations + 1):
            result = algo.train()
            runners = result.get("env_runners", {})
            row = {
                "iteration": i,
                "return_mean": float(runners.get("episode_return_mean", float("nan"))),
                "env_steps": float(
                    result.get("num_env_steps_sampled_lifetime", runners.get("num_env_steps_sampled_lifetime", 0))
                ),
                "seconds": time.perf_counter() - start,
            }
            rows.append(row)
            log(
                f"iter {i:3d}  return {row['return_mean']:6.1f}  env steps {row['env_steps']:8.0f}  "
                f"{row['seconds']:6.1f} s"
            )
            if row["return_mean"] >= target:
                break
    finally:
        algo.stop()
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--iterations", type=int, default=60, help="at most this many training iterations")
    p.add_argument("--target", type=float, default=TARGET_RETURN, help="stop at this mean episode return")
    p.add_argument("--env-runners", type=int, default=1, help="RLlib env runner processes")
    p.add_argument("--envs-per-runner", type=int, default=4, help="remote worlds per env runner")
    p.add_argument("--env", default=ENV_ID, help="a registered remote env id (module:id imports the module)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--address", default=None, help="Ray cluster to join (default: start a local one)")
    args = p.parse_args(argv)

    import ray

    ray.init(address=args.address)
    rows = train(args.iterations, args.target, args.env_runners, args.envs_per_runner, args.seed, env_id=args.env)
    last = rows[-1]
    reached = last["return_mean"] >= args.target
    print(
        f"{'reached' if reached else 'did not reach'} mean return {args.target:g}: "
        f"{last['return_mean']:.1f} after {int(last['iteration'])} iterations, "
        f"{last['env_steps']:.0f} env steps, {last['seconds']:.0f} s"
    )
    return 0 if reached else 1


if __name__ == "__main__":
    sys.exit(main())
