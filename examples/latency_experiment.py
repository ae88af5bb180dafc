"""How much agent latency can a fixed controller take? Real time vs its reproducible twin.

Continuous CartPole is balanced by a fixed LQR controller
(``remoteenv.controllers.cartpole_continuous``) in two ways:

1. ``real_time=True``: the sim runs on the wall clock; before each action the
   agent sleeps ``think`` ms, and the physics keeps going meanwhile with the
   previous action held. The latency each action actually had (sim time from
   the observation it was computed from to the substep where it took effect)
   is read from ``env.unwrapped.latency_stats``.
2. ``action_delay=k`` (lock-step): the same delays expressed in whole control
   ticks, ``k = round(think / dt)`` with dt = 20 ms; every action takes effect
   exactly ``k`` ticks late, and nothing depends on the machine's timing.
   The agent still decides every tick.
3. ``action_delay=k`` with each decision held for ``k + 1`` ticks: in real
   time an agent that thinks k ticks also acts only every k + 1 ticks, and
   this run has exactly that structure, reproducibly.

For each think time it prints the mean episode length (simulated seconds,
capped at ``--max-seconds``) and the mean latency in each mode, and saves a
PNG of episode length against latency for both modes.

Run:  python examples/latency_experiment.py            (about 2 minutes)
      python examples/latency_experiment.py --episodes 5 --think-ms 0 10 20 30 40
The real-time runs take wall time: each episode lasts up to
``--max-seconds / --real-time-factor`` seconds.
"""

from __future__ import annotations

import argparse
import math
import time

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import remoteenv  # noqa: F401  (registers remoteenv/CartPole-v0)
from remoteenv.controllers import cartpole_continuous

ENV_ID = "remoteenv/CartPole-v0"
NO_LIMIT = 10**9  # steps: episodes are cut by simulated time here, not by step count


def run_real_time(think_ms: float, args: argparse.Namespace) -> dict[str, float]:
    """Episodes under real_time=True with ``think_ms`` of sleep before each action."""
    env = gym.make(
        ENV_ID, continuous=True, real_time=True, real_time_factor=args.real_time_factor, max_episode_steps=NO_LIMIT
    )
    lengths = []
    try:
        for episode in range(args.episodes):
            obs, _ = env.reset(seed=args.seed + episode)
            sim_time = 0.0
            while sim_time < args.max_seconds:
                time.sleep(think_ms / 1e3)
                obs, _, terminated, _, info = env.step(cartpole_continuous(obs))
                sim_time = info["sim_time"]
                if terminated:
                    break
            lengths.append(min(sim_time, args.max_seconds))
        stats = env.unwrapped.latency_stats
        return {
            "episode_s": float(np.mean(lengths)),
            "latency_ms": 1e3 * stats.latency_s.mean,
            "late_pct": 100.0 * stats.late_actions / max(stats.steps, 1),
            "overruns": stats.pacing_overruns,
        }
    finally:
        env.close()


def run_action_delay(k: int, args: argparse.Namespace, hold: int = 1) -> dict[str, float]:
    """The same episodes in lock-step with every action taking effect ``k`` ticks
    late; the agent decides every ``hold`` ticks and repeats its action in between."""
    env = gym.make(ENV_ID, continuous=True, action_delay=k, max_episode_steps=NO_LIMIT)
    lengths = []
    try:
        dt = env.unwrapped.dt
        for episode in range(args.episodes):
            obs, _ = env.reset(seed=args.seed + episode)
            steps, max_steps = 0, int(round(args.max_seconds / dt))
            while steps < max_steps:
                if steps % hold == 0:
                    action = cartpole_continuous(obs)
                obs, _, terminated, _, _ = env.step(action)
                steps += 1
                if terminated:
                    break
            lengths.append(steps * dt)
        return {"episode_s": float(np.mean(lengths)), "latency_ms": 1e3 * k * dt}
    finally:
        env.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--think-ms",
        type=float,
        nargs="+",
        default=[0, 5, 10, 20, 40, 60, 80],
        help="agent think times to sweep, ms (default 0 5 10 20 40 60 80)",
    )
    p.add_argument("--episodes", type=int, default=2, help="episodes per setting (default 2)")
    p.add_argument(
        "--max-seconds",
        type=float,
        default=10.0,
        help="cap on an episode's simulated length, s (default 10 = 500 ticks)",
    )
    p.add_argument(
        "--real-time-factor",
        type=float,
        default=1.0,
        help="simulated seconds per wall second in the real-time runs (default 1.0)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    p.add_argument("--out", default="latency_experiment.png", help="where to save the plot")
    args = p.parse_args()

    dt = 0.02  # CartPole's control tick, s
    delay_results: dict[int, dict[str, float]] = {}
    held_results: dict[int, dict[str, float]] = {}
    rows = []
    started = time.monotonic()
    for think in args.think_ms:
        k = int(math.floor(think / (1e3 * dt) + 0.5))  # round half up: 10 ms -> 1 tick
        rt = run_real_time(think, args)
        if k not in delay_results:
            delay_results[k] = run_action_delay(k, args)
            held_results[k] = run_action_delay(k, args, hold=k + 1)
        rows.append((think, rt, k, delay_results[k]))

    print(
        f"continuous CartPole, LQR controller, {args.episodes} episodes per setting, "
        f"episodes capped at {args.max_seconds:g} s sim, real_time_factor {args.real_time_factor:g}"
    )
    print(
        f"{'think':>6} | {'real time: latency':>18} {'late':>5} {'episode':>8} | "
        f"{'action_delay: k':>15} {'latency':>8} {'episode':>8} | {'held k+1: episode':>17}"
    )
    print(f"{'ms':>6} | {'ms (ticks)':>18} {'%':>5} {'s':>8} | {'ticks':>15} {'ms':>8} {'s':>8} | {'s':>17}")
    for think, rt, k, ad in rows:
        lat = f"{rt['latency_ms']:.1f} ({rt['latency_ms'] / (1e3 * dt):.2f})"
        print(
            f"{think:6g} | {lat:>18} {rt['late_pct']:5.0f} {rt['episode_s']:8.2f} | "
            f"{k:15d} {ad['latency_ms']:8.1f} {ad['episode_s']:8.2f} | "
            f"{held_results[k]['episode_s']:17.2f}"
        )
    overruns = sum(rt["overruns"] for _, rt, _, _ in rows)
    print(
        f"sim pacing overruns over all real-time runs: {overruns}; total wall time {time.monotonic() - started:.0f} s"
    )

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.plot(
        [rt["latency_ms"] for _, rt, _, _ in rows],
        [rt["episode_s"] for _, rt, _, _ in rows],
        "o-",
        label="real_time=True (think time slept)",
    )
    for think, rt, _, _ in rows:
        ax.annotate(
            f"{think:g} ms", (rt["latency_ms"], rt["episode_s"]), textcoords="offset points", xytext=(4, 4), fontsize=8
        )
    ks = sorted(delay_results)
    ax.plot(
        [delay_results[k]["latency_ms"] for k in ks],
        [delay_results[k]["episode_s"] for k in ks],
        "s--",
        label="action_delay=k (lock-step), decide every tick",
    )
    ax.plot(
        [held_results[k]["latency_ms"] for k in ks],
        [held_results[k]["episode_s"] for k in ks],
        "^:",
        label="action_delay=k, decision held k+1 ticks",
    )
    ax.set_xlabel("mean action latency (ms of sim time, obs -> action in force)")
    ax.set_ylabel(f"mean episode length (s sim, cap {args.max_seconds:g})")
    ax.set_title("Continuous CartPole, LQR: episode length vs latency")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"plot saved to {args.out}")


if __name__ == "__main__":
    main()
