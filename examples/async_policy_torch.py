"""Overlap a torch policy with physics: RemoteVectorEnv's send/recv (EnvPool's API).

With ``step`` the sims wait while the policy computes and the policy waits
while the sims step. With ``send``/``recv`` and ``batch_size`` = N / 2, the
policy computes actions for one half of the worlds while the sims step the
other half: ``recv`` returns the first ``batch_size`` worlds to finish, with
their indices in ``info["env_id"]``, and ``send`` hands their actions back.

This script runs a small Gaussian MLP policy on Reacher both ways for a few
seconds each and prints env steps per second. Every world's trajectory is
the one ``step`` would give it with the same actions; only the order in
which worlds come back differs. Rollout collection for training works the
same way: file each row of a ``recv`` under its ``env_id``.

    python examples/async_policy_torch.py --num-envs 16 --seconds 5

Needs torch (``pip install torch==2.13.0``).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch
from torch import nn

import remoteenv  # registers remoteenv/Reacher-v0

ENV_ID = "remoteenv/Reacher-v0"


class Policy(nn.Module):
    """Gaussian policy: an MLP for the mean, a learned log std."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int = 256) -> None:
        super().__init__()
        self.mean = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(), nn.Linear(hidden, act_dim)
        )
        self.log_std = nn.Parameter(torch.full((act_dim,), -0.5))

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        mean = self.mean(torch.as_tensor(obs, dtype=torch.float32))
        action = mean + self.log_std.exp() * torch.randn_like(mean)
        return action.clamp(-1.0, 1.0).numpy()


def run_step(env: gym.vector.VectorEnv, policy: Policy, seconds: float) -> float:
    """Synchronous: policy, then physics, then policy ..."""
    obs, _ = env.reset(seed=0)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        obs, *_ = env.step(policy.act(obs))
        steps += env.num_envs
    return steps / (time.perf_counter() - start)


def run_send_recv(env: remoteenv.RemoteVectorEnv, policy: Policy, seconds: float) -> float:
    """Asynchronous: the policy works on one batch while the sims step the others."""
    obs, _ = env.reset(seed=0)
    env.send(policy.act(obs))  # every world starts stepping
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        obs, reward, terminated, truncated, info = env.recv()  # the first batch_size worlds done
        env.send(policy.act(obs), info["env_id"])  # their next actions
        steps += len(info["env_id"])
    elapsed = time.perf_counter() - start
    for _ in range(env.num_envs // env.batch_size):  # collect what is still in flight
        env.recv()
    return steps / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    if args.num_envs < 2 or args.num_envs % 2:
        parser.error("--num-envs must be even and >= 2 (batch_size is half of it)")
    torch.set_num_threads(1)
    env = gym.make_vec(
        ENV_ID, num_envs=args.num_envs, vectorization_mode="vector_entry_point", batch_size=args.num_envs // 2
    )
    try:
        obs_dim = env.single_observation_space.shape[0]
        act_dim = env.single_action_space.shape[0]
        policy = Policy(obs_dim, act_dim)
        sync = run_step(env, policy, args.seconds)
        overlapped = run_send_recv(env.unwrapped, policy, args.seconds)
    finally:
        env.close()
    print(f"step():          {sync:8.0f} env steps/s")
    print(f"send()/recv():   {overlapped:8.0f} env steps/s  ({overlapped / sync:.2f}x)")


if __name__ == "__main__":
    main()
