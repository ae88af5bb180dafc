"""Train Stable-Baselines3 PPO on a registered remote env (default remoteenv/CartPole-v0), save, load, evaluate.

SB3 does not take Gymnasium vector envs; ``remoteenv.integrations.sb3.make_sb3_vec_env``
gives it an SB3 ``VecEnv`` over one RemoteVectorEnv (one request per step for
all worlds of a sim process). The trained model is saved as SB3's zip, loaded
back as a fresh model, and evaluated on a single remote env with SB3's
``evaluate_policy``.

    python examples/train_sb3.py                                      # CartPole, 100k steps
    python examples/train_sb3.py --env my_arm:my_arm/MyArm-v0 --steps 200000
    python examples/train_sb3.py --eval-only --save my_arm_sb3_ppo.zip --env my_arm:my_arm/MyArm-v0
    python examples/train_sb3.py --env-kwargs '{"obs_mode": "pixels"}'  # CartPole from its camera

``--env`` takes any registered id; ``module:id`` imports ``module`` first
(an env package of your own); ``--env-kwargs`` is a JSON map of the env's
keyword arguments (e.g. a camera ``obs_mode``). The policy follows the
observation space (:func:`policy_for`): ``CnnPolicy`` for an image,
``MultiInputPolicy`` for a Dict (e.g. ``{"state", "pixels"}``), else
``MlpPolicy``. Needs ``pip install remoteenv[sb3]`` (install ``torch==2.13.0``
first). SB3's PPO defaults are used; tune them for your env.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import gymnasium as gym
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.vec_env import DummyVecEnv

import remoteenv  # noqa: F401  (registers the shipped scenes' ids)
from remoteenv.cli.arguments import json_map
from remoteenv.integrations.sb3 import make_sb3_vec_env
from remoteenv.registration import find_spec  # "module:id" imports module first, as gym.make does

DEFAULT_ENV = "remoteenv/CartPole-v0"


def policy_for(space: gym.Space) -> str:
    """SB3's policy for an observation space: CNN for an image, multi-input for a Dict."""
    if isinstance(space, gym.spaces.Dict):
        return "MultiInputPolicy"
    if is_image_space(space, check_channels=False):
        return "CnnPolicy"
    return "MlpPolicy"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default=DEFAULT_ENV, help="registered id; module:id imports module first")
    p.add_argument("--steps", type=int, default=100_000, help="env steps to train for")
    p.add_argument("--num-envs", type=int, default=8)
    p.add_argument("--n-steps", type=int, default=2048, help="PPO rollout length per env (SB3's n_steps)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--env-kwargs", default=None, help='env keyword arguments as JSON, e.g. \'{"obs_mode": "pixels"}\'')
    p.add_argument("--save", default=None, help="where to save the model (default: <name>_sb3_ppo.zip)")
    p.add_argument("--eval-only", action="store_true", help="skip training; load --save and evaluate")
    p.add_argument("--eval-episodes", type=int, default=10)
    args = p.parse_args()
    torch.set_num_threads(1)  # small nets: threads only add overhead next to the sims
    spec = find_spec(args.env)
    kwargs = json_map(args.env_kwargs, "--env-kwargs") if args.env_kwargs else {}
    save = args.save or f"{spec.name.lower()}_sb3_ppo.zip"

    if not args.eval_only:
        venv = make_sb3_vec_env(args.env, num_envs=args.num_envs, seed=args.seed, **kwargs)
        try:
            start = time.perf_counter()
            batch = min(64, args.n_steps * args.num_envs)
            policy = policy_for(venv.observation_space)
            print(f"{policy} for observations {venv.observation_space}", flush=True)
            model = PPO(policy, venv, n_steps=args.n_steps, batch_size=batch, seed=args.seed, verbose=0)
            model.learn(args.steps)
            elapsed = time.perf_counter() - start
            model.save(save)
        finally:
            venv.close()
        print(
            f"trained SB3 PPO on {spec.id} for {model.num_timesteps} steps in {elapsed:.1f} s "
            f"({model.num_timesteps / elapsed:.0f} steps/s); saved to {os.path.abspath(save)}"
        )

    model = PPO.load(save)  # a fresh model from the file, as another program would load it
    env = DummyVecEnv([lambda: Monitor(gym.make(spec.id, **kwargs))])  # one remote env, as evaluate_policy wants it
    env.seed(args.seed + 1000)
    try:
        mean, std = evaluate_policy(model, env, n_eval_episodes=args.eval_episodes, deterministic=True)
    finally:
        env.close()
    print(f"evaluation ({args.eval_episodes} episodes, deterministic): return {mean:.2f} +- {std:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
