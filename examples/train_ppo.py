"""Train PPO on a registered remote env (default remoteenv/CartPole-v0), save it, evaluate it.

A compact PPO (clipped surrogate, GAE, actor and critic networks) in
plain torch on the CPU, for any remote env id whose observations are a Box,
an image or a Dict of them and whose actions are Discrete (a categorical
policy) or a Box (a Gaussian policy, actions clipped to the bounds). The
network reads the observation space: flat values go to MLPs as they are; an
image (uint8 ``H x W x C``, e.g. a camera ``obs_mode="pixels"``, stacked
frames too) first goes through a small CNN, one shared by actor and critic;
a Dict (``{"state", "pixels"}``) through one input each, their features side
by side. Flat observations get separate actor and critic MLPs. ``--json``
writes the run's figures. The worlds run in sim
processes (RemoteVectorEnv; by default one process hosts all 8 and steps them
from one request); the agent sees a Gymnasium vector env.

1. Train until the mean return of the last 20 episodes reaches --target
   (default: the id's reward_threshold, 475 for CartPole; none for an id
   without one), or until the step budget is spent (with a target, it then
   says so and exits 1).
2. Save the policy and what it was trained on to --save.
3. Evaluate it: the greedy policy for --eval-episodes lock-step episodes.
   With --think-ms, also with real_time=True: the sim's physics runs on the
   wall clock while the agent thinks, so an agent that thinks for longer than
   a control tick acts on stale observations; the table shows what thinking
   time costs.

    python examples/train_ppo.py                                   # CartPole until solved
    python examples/train_ppo.py --think-ms 0,10,20,40,80          # ... then the real-time table
    python examples/train_ppo.py --env my_arm:my_arm/MyArm-v0 --budget 100000 --save my_arm_ppo.pt
    python examples/train_ppo.py --eval-only --save my_arm_ppo.pt  # load and evaluate again
    python examples/train_ppo.py --env-kwargs '{"obs_mode": "state_pixels"}' --budget 200000
    python examples/train_ppo.py --env-kwargs '{"obs_mode": "pixels", "frame_stack": 4}' --budget 300000 \\
        --reward-scale 0.01 --ent-coef 0.01 --torch-threads 2          # the camera recipe, docs/cameras.md

``--env`` takes any registered id; ``module:id`` imports ``module`` first
(an env package of your own); ``--env-kwargs`` is a JSON map of the env's
keyword arguments (saved with the policy). Needs torch and tqdm (``pip install
torch==2.13.0 tqdm``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from tqdm import tqdm

import remoteenv  # noqa: F401  (registers the shipped scenes' ids)
from remoteenv.cli.arguments import json_map
from remoteenv.registration import find_spec  # "module:id" imports module first, as gym.make does

DEFAULT_ENV = "remoteenv/CartPole-v0"


# ---------------------------------------------------------------- the model


def mlp(n_in: int, n_out: int, out_gain: float) -> nn.Sequential:
    """Two tanh layers of 64 units, orthogonal init (as in the PPO paper's code)."""
    layers = [nn.Linear(n_in, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, n_out)]
    for layer in layers:
        if isinstance(layer, nn.Linear):
            nn.init.orthogonal_(layer.weight, np.sqrt(2) if layer is not layers[-1] else out_gain)
            nn.init.zeros_(layer.bias)
    return nn.Sequential(*layers)


def is_image(shape: tuple[int, ...], dtype: Any) -> bool:
    """An image: uint8 ``H x W x C``, any number of channels (a camera's stacked frames too),
    as SB3's CNN policies read one."""
    return np.dtype(dtype) == np.uint8 and len(shape) == 3


def describe_obs_space(space: gym.Space) -> dict[str, Any]:
    """The observation's inputs, by key (``"obs"`` for a Box): shape and whether
    it is an image (saved with the policy)."""
    boxes = dict(space.spaces) if isinstance(space, gym.spaces.Dict) else {"obs": space}
    inputs = {}
    for key, sub in boxes.items():
        if not isinstance(sub, gym.spaces.Box):
            raise SystemExit(f"this PPO takes Box observations, images and Dicts of them, not {space}")
        inputs[key] = {"shape": list(sub.shape), "image": is_image(sub.shape, sub.dtype)}
    return {"dict": isinstance(space, gym.spaces.Dict), "inputs": inputs}


def small_cnn(shape: list[int]) -> tuple[nn.Module, int]:
    """A small CNN for ``H x W x C`` uint8 images (scaled to [0, 1]): two strided
    convolutions and a linear layer of 128 features; returns it and 128."""
    h, w, c = shape
    conv = nn.Sequential(nn.Conv2d(c, 16, 8, stride=4), nn.ReLU(), nn.Conv2d(16, 32, 4, stride=2), nn.ReLU())
    with torch.no_grad():
        flat = conv(torch.zeros(1, c, h, w)).numel()
    return nn.Sequential(conv, nn.Flatten(), nn.Linear(flat, 128), nn.ReLU()), 128


class Encoder(nn.Module):
    """Observation (a dict of batched tensors, see :func:`as_inputs`) -> feature vector:
    images through :func:`small_cnn`, other inputs flattened, side by side."""

    def __init__(self, obs: dict[str, Any]) -> None:
        super().__init__()
        self.images = nn.ModuleDict()
        self.size = 0
        for key, entry in obs["inputs"].items():
            if entry["image"]:
                self.images[key], n = small_cnn(entry["shape"])
            else:
                n = int(np.prod(entry["shape"]))
            self.size += n

    def forward(self, inputs: dict[str, torch.Tensor]) -> torch.Tensor:
        parts = []
        for key, x in inputs.items():
            if key in self.images:  # N x H x W x C uint8 -> N x C x H x W in [0, 1]
                parts.append(self.images[key](x.permute(0, 3, 1, 2).float().mul_(1 / 255)))
            else:
                parts.append(x.reshape(len(x), -1).float())
        return parts[0] if len(parts) == 1 else torch.cat(parts, dim=-1)


def as_inputs(obs: Any, layout: dict[str, Any], n: int) -> dict[str, torch.Tensor]:
    """``n`` observations (a batch array or a dict of them) as the encoder's input tensors."""
    arrays = obs if layout["dict"] else {"obs": obs}
    out = {}
    for key, entry in layout["inputs"].items():
        x = torch.as_tensor(np.asarray(arrays[key]))
        out[key] = x.reshape(n, *entry["shape"]) if entry["image"] else x.float().reshape(n, *entry["shape"])
    return out


def pick(obs: Any, mask: np.ndarray) -> Any:
    """The observations of the worlds ``mask`` selects (a batch array or a dict of them)."""
    return {k: v[mask] for k, v in obs.items()} if isinstance(obs, dict) else obs[mask]


def describe_action_space(space: gym.Space) -> dict[str, Any]:
    """What the policy needs to know of the action space (saved with it)."""
    if isinstance(space, gym.spaces.Discrete):
        return {"kind": "discrete", "n": int(space.n)}
    if isinstance(space, gym.spaces.Box) and len(space.shape) == 1:
        return {"kind": "box", "dim": space.shape[0], "low": space.low.tolist(), "high": space.high.tolist()}
    raise SystemExit(f"this PPO takes Discrete or flat Box actions, not {space}")


class ActorCritic(nn.Module):
    """A categorical (Discrete) or diagonal Gaussian (Box) policy, and a value
    function. On flat observations each reads them through its own
    :class:`Encoder`; with images they share one (its CNN is most of the
    compute; CleanRL's Atari PPO shares it too), and both losses train it."""

    def __init__(self, obs: dict[str, Any], action: dict[str, Any]) -> None:
        super().__init__()
        self.obs, self.action = obs, action
        self.discrete = action["kind"] == "discrete"
        self.shared = any(entry["image"] for entry in obs["inputs"].values())
        self.actor_in = Encoder(obs)
        self.critic_in = self.actor_in if self.shared else Encoder(obs)
        self.actor = mlp(self.actor_in.size, action["n"] if self.discrete else action["dim"], out_gain=0.01)
        self.critic = mlp(self.critic_in.size, 1, out_gain=1.0)
        if not self.discrete:
            self.log_std = nn.Parameter(torch.zeros(action["dim"]))
            self.register_buffer("low", torch.tensor(action["low"], dtype=torch.float32))
            self.register_buffer("high", torch.tensor(action["high"], dtype=torch.float32))

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.critic(self.critic_in(obs)).squeeze(-1)

    def dist(self, obs: dict[str, torch.Tensor]) -> torch.distributions.Distribution:
        return self._dist(self.actor(self.actor_in(obs)))

    def dist_and_value(self, obs: dict[str, torch.Tensor]) -> tuple[torch.distributions.Distribution, torch.Tensor]:
        """Both heads; a shared encoder runs once."""
        if not self.shared:
            return self.dist(obs), self.value(obs)
        features = self.actor_in(obs)
        return self._dist(self.actor(features)), self.critic(features).squeeze(-1)

    def _dist(self, logits: torch.Tensor) -> torch.distributions.Distribution:
        if self.discrete:
            return torch.distributions.Categorical(logits=logits)
        return torch.distributions.Independent(torch.distributions.Normal(logits, self.log_std.exp()), 1)

    def to_env(self, action: torch.Tensor) -> np.ndarray:
        """A sampled action as the env takes it (Box actions clipped to their bounds)."""
        if self.discrete:
            return action.numpy()
        return torch.max(torch.min(action, self.high), self.low).numpy().astype(np.float32)

    @torch.no_grad()
    def act(self, obs: Any, greedy: bool = False) -> Any:
        """The action for one observation: the most likely (greedy) or a sampled one."""
        one = {k: v[None] for k, v in obs.items()} if isinstance(obs, dict) else np.asarray(obs)[None]
        d = self.dist(as_inputs(one, self.obs, 1))
        if greedy:
            action = d.probs.argmax(-1) if self.discrete else d.mean
        else:
            action = d.sample()
        out = self.to_env(action)[0]
        return int(out) if self.discrete else out


# ---------------------------------------------------------------- training


def train(args: argparse.Namespace) -> tuple[ActorCritic, bool, dict[str, Any]]:
    kwargs = args.env_kwargs
    if args.vectorization == "remote":  # RemoteVectorEnv, the id's vector entry point
        envs = gym.make_vec(
            args.env, num_envs=args.num_envs, vectorization_mode="vector_entry_point", seed=args.seed, **kwargs
        )
    else:  # Gymnasium's SyncVectorEnv over single remote envs, for comparison
        envs = gym.make_vec(args.env, num_envs=args.num_envs, vectorization_mode="sync", **kwargs)
    try:
        return _train(envs, args)
    finally:
        envs.close()


def _train(envs: gym.vector.VectorEnv, args: argparse.Namespace) -> tuple[ActorCritic, bool, dict[str, Any]]:
    torch.manual_seed(args.seed)
    n, T = envs.num_envs, args.rollout_steps
    layout = describe_obs_space(envs.single_observation_space)
    model = ActorCritic(layout, describe_action_space(envs.single_action_space))
    model.to(memory_format=torch.channels_last)  # the images arrive channel-last: ~2x faster convolutions
    act_shape = () if model.discrete else (model.action["dim"],)
    optim = torch.optim.Adam(model.parameters(), lr=args.lr, eps=1e-5)
    # NEXT_STEP autoreset: the step after a done only resets that env; that
    # sample is no transition and is left out of the loss.
    next_step = (
        envs.metadata.get("autoreset_mode", gym.vector.AutoresetMode.NEXT_STEP) == gym.vector.AutoresetMode.NEXT_STEP
    )

    # Images stay uint8 in the buffer (a quarter of the memory); the encoder scales them.
    buf_obs = {
        key: torch.zeros(T, n, *e["shape"], dtype=torch.uint8 if e["image"] else torch.float32)
        for key, e in layout["inputs"].items()
    }
    buf_act = torch.zeros(T, n, *act_shape, dtype=torch.long if model.discrete else torch.float32)
    buf_logp, buf_val, buf_rew = torch.zeros(T, n), torch.zeros(T, n), torch.zeros(T, n)
    buf_done, buf_valid = torch.zeros(T, n), torch.zeros(T, n)

    obs, _ = envs.reset(seed=args.seed)
    resetting = np.zeros(n, dtype=bool)
    ep_return = np.zeros(n)
    recent: deque[float] = deque(maxlen=20)
    episodes, steps, update = 0, 0, 0
    reached = False
    start = time.perf_counter()
    bar = tqdm(total=args.budget, unit="step", desc="PPO", dynamic_ncols=True)
    while steps < args.budget and not reached:
        # ---- collect T steps from each env
        for t in range(T):
            o = as_inputs(obs, layout, n)
            with torch.no_grad():
                d, value = model.dist_and_value(o)
                action = d.sample()
                buf_logp[t], buf_val[t] = d.log_prob(action), value
            for key, x in o.items():
                buf_obs[key][t] = x
            buf_act[t] = action
            buf_valid[t] = torch.as_tensor(~resetting, dtype=torch.float32)
            obs, reward, terminated, truncated, infos = envs.step(model.to_env(action))
            live = ~resetting
            raw = np.asarray(reward, dtype=np.float64) * live
            done = (terminated | truncated) & live
            ep_return += raw
            reward = raw.copy()
            cut = truncated & ~terminated & live
            if cut.any():  # a time limit is no failure: bootstrap from the episode's last obs
                if next_step:
                    final = pick(obs, cut)
                elif layout["dict"]:
                    finals = list(infos["final_obs"][cut])
                    final = {key: np.stack([f[key] for f in finals]) for key in layout["inputs"]}
                else:
                    final = np.stack(list(infos["final_obs"][cut]))
                with torch.no_grad():  # the value is in scaled reward units
                    bootstrap = model.value(as_inputs(final, layout, int(cut.sum()))).numpy()
                    reward[cut] += args.gamma * bootstrap / args.reward_scale
            buf_rew[t] = torch.as_tensor(reward * args.reward_scale, dtype=torch.float32)
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
            next_value = model.value(as_inputs(obs, layout, n))
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
        b_obs = {key: x.reshape(T * n, *x.shape[2:])[valid] for key, x in buf_obs.items()}
        b_act = buf_act.reshape(T * n, *act_shape)[valid]
        b_logp, b_adv, b_ret = buf_logp.reshape(-1)[valid], adv.reshape(-1)[valid], ret.reshape(-1)[valid]
        for g in optim.param_groups:  # linear learning-rate decay over the budget
            g["lr"] = args.lr * max(0.0, 1.0 - steps / args.budget)
        for _ in range(args.epochs):
            for idx in torch.randperm(len(b_act)).split(args.minibatch):
                mb_obs = {key: x[idx] for key, x in b_obs.items()}
                d, value = model.dist_and_value(mb_obs)
                ratio = torch.exp(d.log_prob(b_act[idx]) - b_logp[idx])
                a = b_adv[idx]
                a = (a - a.mean()) / (a.std() + 1e-8)
                policy_loss = -torch.min(ratio * a, ratio.clamp(1 - args.clip, 1 + args.clip) * a).mean()
                value_loss = 0.5 * (value - b_ret[idx]).pow(2).mean()
                loss = policy_loss + args.vf_coef * value_loss - args.ent_coef * d.entropy().mean()
                optim.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), 0.5)
                optim.step()

        update += 1
        mean20 = float(np.mean(recent)) if recent else float("nan")
        elapsed = time.perf_counter() - start
        bar.set_postfix(episodes=episodes, mean20=f"{mean20:.1f}")
        if update % args.log_every == 0:
            tqdm.write(
                f"update {update:4d}  steps {steps:7d}  episodes {episodes:5d}  "
                f"mean return (last 20) {mean20:8.2f}  {steps / elapsed:6.0f} steps/s"
            )
        reached = args.target is not None and len(recent) == 20 and mean20 >= args.target
    bar.close()
    elapsed = time.perf_counter() - start
    mean20 = float(np.mean(recent)) if recent else float("nan")
    if args.target is None:
        verdict = "trained"
    elif reached:
        verdict = f"reached the target {args.target:g}"
    else:
        verdict = f"did NOT reach the target {args.target:g} within the budget of {args.budget} steps"
    print(
        f"{verdict}: mean return of the last 20 episodes {mean20:.2f} after {steps} steps, "
        f"{episodes} episodes, {elapsed:.1f} s wall ({steps / elapsed:.0f} steps/s)"
    )
    summary = {
        "steps": steps,
        "episodes": episodes,
        "updates": update,
        "train_wall_s": round(elapsed, 1),
        "steps_per_s": round(steps / elapsed),
        "mean_return_last_20": mean20,
        "reached_target": reached,
    }
    return model, reached or args.target is None, summary


# ---------------------------------------------------------------- saving and evaluation


def save(model: ActorCritic, path: str, env_id: str, env_kwargs: dict[str, Any]) -> None:
    """The policy and what rebuilding it needs: the env id (as given, ``module:`` and
    all) and its kwargs, the observation's inputs, the action space."""
    saved = {"env_id": env_id, "env_kwargs": env_kwargs, "obs": model.obs, "action": model.action}
    torch.save({**saved, "state": model.state_dict()}, path)
    print(f"saved the policy to {os.path.abspath(path)}")


def load(path: str) -> tuple[ActorCritic, str, dict[str, Any]]:
    saved = torch.load(path)
    model = ActorCritic(saved["obs"], saved["action"])
    model.load_state_dict(saved["state"])
    return model, saved["env_id"], saved.get("env_kwargs", {})


def evaluate(model: ActorCritic, env_id: str, episodes: int, seed: int, env_kwargs: dict[str, Any]) -> dict[str, float]:
    """The greedy policy for ``episodes`` lock-step episodes: mean return and length."""
    env = gym.make(env_id, **env_kwargs)
    try:
        returns, lengths = [], []
        for e in range(episodes):
            obs, _ = env.reset(seed=seed + e)
            ret, steps, done = 0.0, 0, False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(model.act(obs, greedy=True))
                ret += float(reward)
                steps += 1
                done = terminated or truncated
            returns.append(ret)
            lengths.append(steps)
    finally:
        env.close()
    print(
        f"evaluation ({episodes} lock-step episodes, greedy): return {np.mean(returns):.2f} "
        f"+- {np.std(returns):.2f}, length {np.mean(lengths):.1f}"
    )
    return {
        "episodes": episodes,
        "return_mean": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "length_mean": float(np.mean(lengths)),
    }


def evaluate_real_time(
    model: ActorCritic, env_id: str, think_times_ms: list[float], episodes: int, seed: int, env_kwargs: dict[str, Any]
) -> None:
    """Run the greedy policy with real_time=True, sleeping ``think`` ms before each action.

    In real time the reward of a step is summed over every control tick since
    the previous reply (for CartPole: the return counts the ticks the pole
    stayed up), while the time limit counts the agent's steps: a slow agent
    that still balances collects more than the limit."""
    env = gym.make(env_id, real_time=True, **env_kwargs)
    dt_ms = 1000 * env.unwrapped.dt
    print(
        f"\nreal-time evaluation, {episodes} episode(s) per think time "
        f"(control tick {dt_ms:g} ms; the sim does not wait for the agent):"
    )
    print(f"{'think ms':>9} {'return':>10} {'agent steps':>12} {'ended':>6} {'latency ticks':>14} {'late steps':>11}")
    try:
        for think in think_times_ms:
            returns, lengths, latencies, ended, late = [], [], [], 0, 0
            for e in range(episodes):
                obs, _ = env.reset(seed=seed + e)
                ret, steps, done = 0.0, 0, False
                while not done:
                    action = model.act(obs, greedy=True)
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
                ended += bool(terminated)
            lat = f"{np.mean(latencies):.2f}" if latencies else "n/a"
            print(
                f"{think:9.0f} {np.mean(returns):10.1f} {np.mean(lengths):12.1f} "
                f"{ended:2d}/{episodes:<2d} {lat:>14} {100 * late / max(sum(lengths), 1):10.0f}%",
                flush=True,
            )
    finally:
        env.close()


def write_json(args: argparse.Namespace, trained: Any, evaluation: dict[str, float], load_before: Any) -> None:
    """The run's command, training and evaluation figures and load averages, as JSON at ``args.json``."""
    record = {
        "command": " ".join(sys.argv),
        "env": args.env,
        "env_kwargs": args.env_kwargs,
        "budget": args.budget,
        "num_envs": args.num_envs,
        "seed": args.seed,
        "hyperparameters": {
            key: getattr(args, key)
            for key in ("rollout_steps", "epochs", "minibatch", "lr", "ent_coef", "reward_scale", "torch_threads")
        },
        "training": trained,
        "evaluation": evaluation,
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
        "cpus": os.cpu_count(),
    }
    with open(args.json, "w", encoding="utf-8") as f:
        json.dump(record, f, indent=2)
        f.write("\n")
    print(f"wrote {os.path.abspath(args.json)}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--env", default=None, help=f"registered id, module:id to import module first (default {DEFAULT_ENV})"
    )
    p.add_argument("--env-kwargs", default=None, help='env keyword arguments as JSON, e.g. \'{"obs_mode": "pixels"}\'')
    p.add_argument("--num-envs", type=int, default=8)
    p.add_argument(
        "--vectorization",
        choices=["remote", "sync"],
        default="remote",
        help="remote: RemoteVectorEnv (default); sync: gymnasium SyncVectorEnv of remote envs",
    )
    p.add_argument("--budget", type=int, default=500_000, help="env steps before giving up")
    p.add_argument("--target", type=float, default=None, help="stop at this mean return (default: the id's)")
    p.add_argument("--rollout-steps", type=int, default=128, help="steps per env per update")
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--minibatch", type=int, default=256)
    p.add_argument("--lr", type=float, default=2.5e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--clip", type=float, default=0.2)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument(
        "--reward-scale",
        type=float,
        default=1.0,
        help="multiply rewards by this for learning (value targets near 1; returns are logged unscaled)",
    )
    p.add_argument("--torch-threads", type=int, default=1, help="torch's CPU threads (1: the sims keep the rest)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--log-every", type=int, default=10, help="updates between log lines")
    p.add_argument("--save", default=None, help="where to save the policy (default: <Name>_ppo.pt)")
    p.add_argument("--eval-only", action="store_true", help="skip training; load --save and evaluate")
    p.add_argument("--eval-episodes", type=int, default=5)
    p.add_argument("--think-ms", default="", help="real-time evaluation at these think times, ms (e.g. 0,10,20)")
    p.add_argument("--json", default=None, help="also write the run's figures (training, evaluation, load) here")
    args = p.parse_args()
    if not args.reward_scale > 0:
        p.error(f"--reward-scale must be > 0, got {args.reward_scale}")
    torch.set_num_threads(args.torch_threads)  # small nets: by default one, the sims keep the other CPUs

    ok, trained = True, None
    load_before = os.getloadavg()
    args.env_kwargs = json_map(args.env_kwargs, "--env-kwargs") if args.env_kwargs else {}
    if args.eval_only:
        if args.save is None:
            p.error("--eval-only needs --save (the saved policy)")
        model, saved_env, saved_kwargs = load(args.save)
        args.env_kwargs = args.env_kwargs or saved_kwargs
        args.env = find_spec(args.env or saved_env).id  # imports the env's module, if named
    else:
        given = args.env or DEFAULT_ENV
        spec = find_spec(given)
        args.env = spec.id  # the module (if any) is imported now
        if args.target is None:
            args.target = spec.reward_threshold
        args.save = args.save or f"{spec.name.lower()}_ppo.pt"
        model, ok, trained = train(args)
        save(model, args.save, given, args.env_kwargs)
    evaluation = evaluate(model, args.env, args.eval_episodes, args.seed + 1000, args.env_kwargs)
    if args.json:
        write_json(args, trained, evaluation, load_before)
    if args.think_ms:
        think = [float(x) for x in args.think_ms.split(",")]
        evaluate_real_time(model, args.env, think, max(1, min(args.eval_episodes, 2)), args.seed, args.env_kwargs)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
