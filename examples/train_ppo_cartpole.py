"""Train PPO on remoteenv/CartPole-v0 with 8 remote envs, then test it in real time.

A compact PPO (clipped surrogate, GAE, separate actor and critic MLPs) in
plain torch on the CPU. The 8 CartPole worlds run in sim processes
(RemoteVectorEnv; by default one process hosts all 8 and steps them from one
request); the agent sees a Gymnasium vector env.

1. Train until the mean return of the last 20 episodes is >= 475 (of at most
   500), or until the step budget is spent (then it says so and exits 1).
2. Save the policy to --save.
3. Evaluate it with real_time=True: the sim's physics runs on the wall clock
   while the agent thinks, so an agent that thinks for longer than a control
   tick (0.02 s) acts on stale observations. The table shows what thinking
   time costs.

    python examples/train_ppo_cartpole.py
    python examples/train_ppo_cartpole.py --eval-only --save cartpole_ppo.pt

Needs torch and tqdm (``pip install torch==2.13.0 tqdm``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import deque

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from tqdm import tqdm

import remoteenv  # noqa: F401  (registers remoteenv/CartPole-v0)

ENV_ID = "remoteenv/CartPole-v0"
SOLVED = 475.0


# ---------------------------------------------------------------- the model


def mlp(n_in: int, n_out: int, out_gain: float) -> nn.Sequential:
    """Two tanh layers of 64 units, orthogonal init (as in the PPO paper's code)."""
    layers = [nn.Linear(n_in, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, n_out)]
    for layer in layers:
        if isinstance(layer, nn.Linear):
            nn.init.orthogonal_(layer.weight, np.sqrt(2) if layer is not layers[-1] else out_gain)
            nn.init.zeros_(layer.bias)
    return nn.Sequential(*layers)


class ActorCritic(nn.Module):
    def __init__(self, obs_dim: int, n_actions: int) -> None:
        super().__init__()
        self.actor = mlp(obs_dim, n_actions, out_gain=0.01)
        self.critic = mlp(obs_dim, 1, out_gain=1.0)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def dist(self, obs: torch.Tensor) -> torch.distributions.Categorical:
        return torch.distributions.Categorical(logits=self.actor(obs))

    @torch.no_grad()
    def act(self, obs: np.ndarray, greedy: bool = False) -> np.ndarray:
        d = self.dist(torch.as_tensor(obs, dtype=torch.float32))
        return (d.probs.argmax(-1) if greedy else d.sample()).numpy()


# ---------------------------------------------------------------- training


def train(args: argparse.Namespace) -> tuple[ActorCritic, bool]:
    if args.vectorization == "remote":  # RemoteVectorEnv, the id's vector entry point
        envs = gym.make_vec(ENV_ID, num_envs=args.num_envs, vectorization_mode="vector_entry_point", seed=args.seed)
    else:  # Gymnasium's SyncVectorEnv over single remote envs, for comparison
        envs = gym.make_vec(ENV_ID, num_envs=args.num_envs, vectorization_mode="sync")
    try:
        return _train(envs, args)
    finally:
        envs.close()


def _train(envs: gym.vector.VectorEnv, args: argparse.Namespace) -> tuple[ActorCritic, bool]:
    torch.manual_seed(args.seed)
    n, T = envs.num_envs, args.rollout_steps
    obs_dim = envs.single_observation_space.shape[0]
    model = ActorCritic(obs_dim, envs.single_action_space.n)
    optim = torch.optim.Adam(model.parameters(), lr=args.lr, eps=1e-5)
    # NEXT_STEP autoreset: the step after a done only resets that env; that
    # sample is no transition and is left out of the loss.
    next_step = (
        envs.metadata.get("autoreset_mode", gym.vector.AutoresetMode.NEXT_STEP) == gym.vector.AutoresetMode.NEXT_STEP
    )

    buf_obs = torch.zeros(T, n, obs_dim)
    buf_act = torch.zeros(T, n, dtype=torch.long)
    buf_logp, buf_val, buf_rew = torch.zeros(T, n), torch.zeros(T, n), torch.zeros(T, n)
    buf_done, buf_valid = torch.zeros(T, n), torch.zeros(T, n)

    obs, _ = envs.reset(seed=args.seed)
    resetting = np.zeros(n, dtype=bool)
    ep_return = np.zeros(n)
    recent: deque[float] = deque(maxlen=20)
    episodes, steps, update = 0, 0, 0
    solved = False
    start = time.perf_counter()
    bar = tqdm(total=args.budget, unit="step", desc="PPO", dynamic_ncols=True)
    while steps < args.budget and not solved:
        # ---- collect T steps from each env
        for t in range(T):
            o = torch.as_tensor(obs, dtype=torch.float32)
            with torch.no_grad():
                d = model.dist(o)
                action = d.sample()
                buf_logp[t], buf_val[t] = d.log_prob(action), model.value(o)
            buf_obs[t], buf_act[t] = o, action
            buf_valid[t] = torch.as_tensor(~resetting, dtype=torch.float32)
            obs, reward, terminated, truncated, infos = envs.step(action.numpy())
            live = ~resetting
            raw = np.asarray(reward, dtype=np.float64) * live
            done = (terminated | truncated) & live
            ep_return += raw
            reward = raw.copy()
            cut = truncated & ~terminated & live
            if cut.any():  # a time limit is no failure: bootstrap from the episode's last obs
                final = obs[cut] if next_step else np.stack(list(infos["final_obs"][cut]))
                with torch.no_grad():
                    reward[cut] += args.gamma * model.value(torch.as_tensor(final, dtype=torch.float32)).numpy()
            buf_rew[t] = torch.as_tensor(reward, dtype=torch.float32)
            buf_done[t] = torch.as_tensor(done, dtype=torch.float32)
            for i in np.flatnonzero(done):
                recent.append(float(ep_return[i]))
                episodes += 1
                ep_return[i] = 0.0
            resetting = done if next_step else np.zeros(n, dtype=bool)
        steps += T * n
        bar.update(T * n)

        # ---- advantages (GAE); a done cuts the chain
        with torch.no_grad():
            next_value = model.value(torch.as_tensor(obs, dtype=torch.float32))
            adv = torch.zeros(T, n)
            last = torch.zeros(n)
            for t in reversed(range(T)):
                nv = next_value if t == T - 1 else buf_val[t + 1]
                keep = 1.0 - buf_done[t]
                delta = buf_rew[t] + args.gamma * nv * keep - buf_val[t]
                last = delta + args.gamma * args.gae_lambda * keep * last
                adv[t] = last
            ret = adv + buf_val

        # ---- PPO epochs over shuffled minibatches of valid samples
        valid = buf_valid.reshape(-1).bool()
        b_obs, b_act = buf_obs.reshape(-1, obs_dim)[valid], buf_act.reshape(-1)[valid]
        b_logp, b_adv, b_ret = buf_logp.reshape(-1)[valid], adv.reshape(-1)[valid], ret.reshape(-1)[valid]
        for g in optim.param_groups:  # linear learning-rate decay over the budget
            g["lr"] = args.lr * max(0.0, 1.0 - steps / args.budget)
        for _ in range(args.epochs):
            for idx in torch.randperm(len(b_obs)).split(args.minibatch):
                d = model.dist(b_obs[idx])
                ratio = torch.exp(d.log_prob(b_act[idx]) - b_logp[idx])
                a = b_adv[idx]
                a = (a - a.mean()) / (a.std() + 1e-8)
                policy_loss = -torch.min(ratio * a, ratio.clamp(1 - args.clip, 1 + args.clip) * a).mean()
                value_loss = 0.5 * (model.value(b_obs[idx]) - b_ret[idx]).pow(2).mean()
                loss = policy_loss + args.vf_coef * value_loss - args.ent_coef * d.entropy().mean()
                optim.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), 0.5)
                optim.step()

        update += 1
        mean20 = float(np.mean(recent)) if recent else 0.0
        elapsed = time.perf_counter() - start
        bar.set_postfix(episodes=episodes, mean20=f"{mean20:.1f}")
        if update % args.log_every == 0:
            tqdm.write(
                f"update {update:4d}  steps {steps:7d}  episodes {episodes:5d}  "
                f"mean return (last 20) {mean20:6.1f}  {steps / elapsed:6.0f} steps/s"
            )
        solved = len(recent) == 20 and mean20 >= SOLVED
    bar.close()
    elapsed = time.perf_counter() - start
    mean20 = float(np.mean(recent)) if recent else 0.0
    verdict = "solved" if solved else f"NOT solved within the budget of {args.budget} steps"
    print(
        f"{verdict}: mean return of the last 20 episodes {mean20:.1f} after {steps} steps, "
        f"{episodes} episodes, {elapsed:.1f} s wall ({steps / elapsed:.0f} steps/s)"
    )
    return model, solved


# ---------------------------------------------------------------- real-time evaluation


def evaluate_real_time(model: ActorCritic, think_times_ms: list[float], episodes: int, seed: int) -> None:
    """Run the greedy policy with real_time=True, sleeping ``think`` ms before each action.

    In real time the reward of a step is summed over every control tick since
    the previous reply, so the return counts the ticks (0.02 s each) the pole
    stayed up, while the 500-step time limit counts the agent's steps: a slow
    agent that still balances collects more than 500."""
    print(
        f"\nreal-time evaluation, {episodes} episode(s) per think time "
        "(control tick 20 ms; the sim does not wait for the agent):"
    )
    print(
        f"{'think ms':>9} {'return (ticks up)':>18} {'agent steps':>12} {'fell':>5} "
        f"{'latency ticks':>14} {'late steps':>11}"
    )
    env = gym.make(ENV_ID, real_time=True)
    try:
        for think in think_times_ms:
            returns, lengths, latencies, fell, late = [], [], [], 0, 0
            for e in range(episodes):
                obs, _ = env.reset(seed=seed + e)
                ret, steps, done = 0.0, 0, False
                while not done:
                    action = int(model.act(obs, greedy=True))
                    if think:
                        time.sleep(think / 1000)
                    obs, reward, terminated, truncated, info = env.step(action)
                    ret += float(reward)
                    steps += 1
                    done = terminated or truncated
                    if info.get("latency_ticks") is not None:
                        latencies.append(info["latency_ticks"])
                    late += bool(info.get("late"))
                returns.append(ret)
                lengths.append(steps)
                fell += bool(terminated)
            lat = f"{np.mean(latencies):.2f}" if latencies else "n/a"
            print(
                f"{think:9.0f} {np.mean(returns):18.1f} {np.mean(lengths):12.1f} "
                f"{fell:2d}/{episodes:<2d} {lat:>14} {100 * late / max(sum(lengths), 1):10.0f}%",
                flush=True,
            )
    finally:
        env.close()


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--num-envs", type=int, default=8)
    p.add_argument(
        "--vectorization",
        choices=["remote", "sync"],
        default="remote",
        help="remote: RemoteVectorEnv (default); sync: gymnasium SyncVectorEnv of remote envs",
    )
    p.add_argument("--budget", type=int, default=500_000, help="env steps before giving up")
    p.add_argument("--rollout-steps", type=int, default=128, help="steps per env per update")
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--minibatch", type=int, default=256)
    p.add_argument("--lr", type=float, default=2.5e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--clip", type=float, default=0.2)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--log-every", type=int, default=10, help="updates between log lines")
    p.add_argument("--save", default="cartpole_ppo.pt", help="where to save the policy")
    p.add_argument("--eval-only", action="store_true", help="skip training; load --save")
    p.add_argument("--think-ms", default="0,10,20,40,80", help="think times to evaluate, ms")
    p.add_argument("--eval-episodes", type=int, default=2)
    args = p.parse_args()
    torch.set_num_threads(1)  # small nets: threads only add overhead next to the sims

    solved = True
    if args.eval_only:
        model = ActorCritic(4, 2)
        model.load_state_dict(torch.load(args.save))
    else:
        model, solved = train(args)
        torch.save(model.state_dict(), args.save)
        print(f"saved the policy to {os.path.abspath(args.save)}")
    evaluate_real_time(model, [float(x) for x in args.think_ms.split(",")], args.eval_episodes, args.seed)
    return 0 if solved else 1


if __name__ == "__main__":
    sys.exit(main())
