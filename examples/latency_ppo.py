"""Does a delay-aware observation help a policy trained under random action delay?

PPO (plain torch, CPU) learns to balance continuous CartPole while every
action takes effect ``Uniform(0, 3)`` control ticks late (lock-step, so each
run repeats from its seed). Two variants, several seeds each:

- ``plain``: the policy sees the (undelayed) observation only;
- ``history``: the observation followed by the last ``k`` actions sent
  (:class:`remoteenv.wrappers.ActionHistoryVector`, ``k = 4``): with the
  actions still in flight known, the delayed problem is close to Markov again.

Every trained policy (its deterministic mean action) is then evaluated

1. in lock-step with a constant ``action_delay`` of 0..4 ticks, and
2. under ``real_time=True`` with a think time of 0..4 ticks of wall time
   before each action (the world keeps moving meanwhile; episodes cut at
   ``--rt-steps`` steps).

It prints a table (mean return over seeds, with the spread over seeds) and
saves it as JSON and a plot. ``docs/latency.md`` shows one run's result.

    python examples/latency_ppo.py                       # the documented run
    python examples/latency_ppo.py --seeds 0 --budget 20000 --rt-steps 50   # a quick look

Needs torch, tqdm and matplotlib.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from typing import Any

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

import remoteenv
from remoteenv import RemoteVectorEnv
from remoteenv.delays import Uniform
from remoteenv.wrappers import ActionHistoryVector

HISTORY = 4
TRAIN_DELAY = Uniform(0, 3)


# ---------------------------------------------------------------- the model


def mlp(n_in: int, n_out: int, last_gain: float) -> nn.Sequential:
    net = nn.Sequential(nn.Linear(n_in, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, n_out))
    for i, layer in enumerate(net):
        if isinstance(layer, nn.Linear):
            nn.init.orthogonal_(layer.weight, last_gain if i == len(net) - 1 else float(np.sqrt(2)))
            nn.init.zeros_(layer.bias)
    return net


class Gaussian(nn.Module):
    """A diagonal Gaussian policy (state-independent spread) and a value critic."""

    def __init__(self, obs_dim: int, act_dim: int) -> None:
        super().__init__()
        self.mean = mlp(obs_dim, act_dim, 0.01)
        self.log_std = nn.Parameter(torch.full((act_dim,), -0.5))
        self.critic = mlp(obs_dim, 1, 1.0)

    def dist(self, obs: torch.Tensor) -> torch.distributions.Normal:
        return torch.distributions.Normal(self.mean(obs), self.log_std.exp())

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)


class Deterministic(nn.Module):
    """The mean action, clipped to the action space: what is evaluated and saved."""

    def __init__(self, model: Gaussian) -> None:
        super().__init__()
        self.mean = model.mean

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.mean(obs).clamp(-1.0, 1.0)


# ---------------------------------------------------------------- training


def make_vec(num_envs: int, history: bool, **kwargs: Any) -> Any:
    env: Any = RemoteVectorEnv(
        remoteenv.scene_path("cartpole"), num_envs=num_envs, continuous=True, max_episode_steps=500, **kwargs
    )
    return ActionHistoryVector(env, HISTORY) if history else env


def train(history: bool, seed: int, args: argparse.Namespace) -> tuple[Deterministic, list[float]]:
    """PPO for ``args.budget`` steps under the training delay; the policy and its episode returns."""
    torch.manual_seed(seed)
    env = make_vec(args.num_envs, history, action_delay=TRAIN_DELAY)
    try:
        return _train(env, seed, args, f"{'history' if history else 'plain'} seed {seed}")
    finally:
        env.close()


def _train(
    env: Any, seed: int, args: argparse.Namespace, label: str, pause_updates: bool = False
) -> tuple[Deterministic, list[float]]:
    """PPO on the vector ``env``; with ``pause_updates`` (real time) each update
    runs inside ``env.unwrapped.paused()``, so the world waits for the learner."""
    n, T, gamma, lam = env.num_envs, args.rollout, 0.99, 0.95
    obs_dim = env.single_observation_space.shape[0]
    model = Gaussian(obs_dim, 1)
    optim = torch.optim.Adam(model.parameters(), lr=3e-4, eps=1e-5)
    obs_buf, act_buf = torch.zeros(T, n, obs_dim), torch.zeros(T, n, 1)
    logp_buf, val_buf, rew_buf = torch.zeros(T, n), torch.zeros(T, n), torch.zeros(T, n)
    done_buf, live_buf = torch.zeros(T, n), torch.zeros(T, n)
    obs, _ = env.reset(seed=seed)
    resetting = np.zeros(n, dtype=bool)  # NEXT_STEP autoreset: this step only resets the world
    ep_ret, returns = np.zeros(n), []
    steps = 0
    bar = tqdm(total=args.budget, unit="step", desc=label, leave=False)
    while steps < args.budget:
        for t in range(T):
            o = torch.as_tensor(obs, dtype=torch.float32)
            with torch.no_grad():
                d = model.dist(o)
                a = d.sample()
                logp_buf[t], val_buf[t] = d.log_prob(a).sum(-1), model.value(o)
            obs_buf[t], act_buf[t] = o, a
            live_buf[t] = torch.as_tensor(~resetting, dtype=torch.float32)
            obs, reward, terminated, truncated, _ = env.step(a.clamp(-1, 1).numpy())
            live = ~resetting
            done = (terminated | truncated) & live
            r = np.asarray(reward, dtype=np.float64) * live
            ep_ret += r
            cut = truncated & ~terminated & live
            if cut.any():  # the time limit is no failure: bootstrap from the last observation
                with torch.no_grad():
                    r[cut] += gamma * model.value(torch.as_tensor(obs[cut], dtype=torch.float32)).numpy()
            rew_buf[t], done_buf[t] = torch.as_tensor(r), torch.as_tensor(done, dtype=torch.float32)
            for i in np.flatnonzero(done):
                returns.append(float(ep_ret[i]))
                ep_ret[i] = 0.0
            resetting = done
        steps += T * n
        bar.update(T * n)
        with torch.no_grad():
            adv, last = torch.zeros(T, n), torch.zeros(n)
            next_v = model.value(torch.as_tensor(obs, dtype=torch.float32))
            for t in reversed(range(T)):
                keep = 1.0 - done_buf[t]
                delta = rew_buf[t] + gamma * next_v * keep - val_buf[t]
                last = delta + gamma * lam * keep * last
                adv[t], next_v = last, val_buf[t]
            ret = adv + val_buf
        valid = live_buf.reshape(-1).bool()
        b = [x.reshape(-1, *x.shape[2:])[valid] for x in (obs_buf, act_buf, logp_buf, adv, ret)]
        for g in optim.param_groups:
            g["lr"] = 3e-4 * max(0.05, 1.0 - steps / args.budget)
        with env.unwrapped.paused() if pause_updates else contextlib.nullcontext():
            update(model, optim, b, args)
        recent = returns[-20:]
        bar.set_postfix(mean20=f"{np.mean(recent) if recent else 0:.0f}")
    bar.close()
    return Deterministic(model).eval(), returns


def update(model: Gaussian, optim: torch.optim.Optimizer, b: list[torch.Tensor], args: argparse.Namespace) -> None:
    """PPO's epochs of clipped-surrogate minibatch steps over one rollout."""
    for _ in range(args.epochs):
        for idx in torch.randperm(len(b[0])).split(args.minibatch):
            o, a, old_logp, ad, rt = (x[idx] for x in b)
            d = model.dist(o)
            ratio = (d.log_prob(a).sum(-1) - old_logp).exp()
            ad = (ad - ad.mean()) / (ad.std() + 1e-8)
            pg = -torch.min(ratio * ad, ratio.clamp(0.8, 1.2) * ad).mean()
            vf = 0.5 * (model.value(o) - rt).pow(2).mean()
            optim.zero_grad()
            (pg + 0.5 * vf).backward()
            nn.utils.clip_grad_norm_(model.parameters(), 0.5)
            optim.step()


# ---------------------------------------------------------------- evaluation


def first_episodes(env: Any, policy: Deterministic, seed: int, think_s: float, max_ticks: int) -> list[float]:
    """The return of the first episode of every world, cut at ``max_ticks`` control
    ticks (CartPole pays 1 per tick: the return is the ticks balanced; in real
    time one step may span several ticks, and its reward sums them)."""
    obs, _ = env.reset(seed=seed)
    n = env.num_envs
    total, finished = np.zeros(n), np.zeros(n, dtype=bool)
    while True:
        if think_s:
            time.sleep(think_s)
        with torch.no_grad():
            action = policy(torch.as_tensor(obs, dtype=torch.float32)).numpy()
        obs, reward, terminated, truncated, _ = env.step(action)
        total += np.asarray(reward) * ~finished
        finished |= terminated | truncated | (total >= max_ticks)
        if finished.all():
            return np.minimum(total, max_ticks).tolist()


def evaluate(policies: dict[str, list[Deterministic]], args: argparse.Namespace) -> dict[str, Any]:
    """Mean return per (variant, mode, delay, seed) over the eval worlds."""
    results: dict[str, Any] = {v: {"lock_step": {}, "real_time": {}} for v in policies}
    for d in tqdm(range(5), desc="evaluate", leave=False):
        for variant, models in policies.items():
            history = variant == "history"
            env = make_vec(args.eval_envs, history, action_delay=d)
            try:
                results[variant]["lock_step"][d] = [
                    float(np.mean(first_episodes(env, m, 1000 + s, 0.0, 500))) for s, m in enumerate(models)
                ]
            finally:
                env.close()
            env = make_vec(args.rt_envs, history, real_time=True)
            try:
                think = d * float(env.unwrapped.dt if hasattr(env, "unwrapped") else 0.02)
                results[variant]["real_time"][d] = [
                    float(np.mean(first_episodes(env, m, 2000 + s, think, args.rt_steps))) for s, m in enumerate(models)
                ]
            finally:
                env.close()
    return results


def report(results: dict[str, Any], args: argparse.Namespace, wall: float) -> None:
    lines = [
        "| variant | mode | " + " | ".join(f"d={d}" for d in range(5)) + " |",
        "|---|---|" + "---|" * 5,
    ]
    for variant, modes in results.items():
        for mode, by_delay in modes.items():
            cells = [f"{np.mean(v):.0f} ({np.min(v):.0f}–{np.max(v):.0f})" for v in (by_delay[d] for d in range(5))]
            lines.append(f"| {variant} | {mode} | " + " | ".join(cells) + " |")
    table = "\n".join(lines)
    print(table)
    print(f"whole run: {wall:.0f} s wall; load average {os.getloadavg()[0]:.1f}")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "latency_ppo.json"), "w") as f:
        json.dump({"config": vars(args), "wall_s": wall, "results": results, "table": table}, f, indent=1)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), sharey=False)
    for ax, mode, xlabel in zip(axes, ("lock_step", "real_time"), ("action_delay (ticks)", "think time (ticks)")):
        for variant, modes in results.items():
            vals = [modes[mode][d] for d in range(5)]
            line = ax.plot(range(5), [np.mean(v) for v in vals], marker="o", label=variant)[0]
            ax.fill_between(range(5), [min(v) for v in vals], [max(v) for v in vals], alpha=0.2, color=line.get_color())
        ax.set_xlabel(xlabel)
        ax.set_title(mode.replace("_", "-") + (f", {args.rt_steps} ticks max" if mode == "real_time" else ", 500 max"))
        ax.legend(fontsize=8)
    axes[0].set_ylabel("return (mean over seeds; band: their range)")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "latency_ppo.png"), dpi=110)
    plt.close(fig)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--budget", type=int, default=80_000, help="env steps per training run")
    p.add_argument("--num-envs", type=int, default=8)
    p.add_argument("--rollout", type=int, default=128, help="steps per world per update")
    p.add_argument("--epochs", type=int, default=6)
    p.add_argument("--minibatch", type=int, default=256)
    p.add_argument("--eval-envs", type=int, default=6, help="lock-step evaluation episodes per policy and delay")
    p.add_argument("--rt-envs", type=int, default=3, help="real-time evaluation episodes per policy and think time")
    p.add_argument("--rt-steps", type=int, default=100, help="real-time evaluation episodes are cut at this many ticks")
    p.add_argument("--out", default="latency-ppo")
    args = p.parse_args()
    torch.set_num_threads(1)
    start = time.perf_counter()
    policies: dict[str, list[Deterministic]] = {"plain": [], "history": []}
    for variant in policies:
        for seed in args.seeds:
            t0 = time.perf_counter()
            policy, returns = train(variant == "history", seed, args)
            policies[variant].append(policy)
            last = np.mean(returns[-20:]) if returns else 0.0
            print(f"trained {variant:7s} seed {seed}: last-20 return {last:6.1f} in {time.perf_counter() - t0:.0f} s")
            path = os.path.join(args.out, f"policy_{variant}_{seed}.pt")
            os.makedirs(args.out, exist_ok=True)
            torch.jit.trace(policy, torch.zeros(1, policy.mean[0].in_features)).save(path)
    results = evaluate(policies, args)
    report(results, args, time.perf_counter() - start)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
