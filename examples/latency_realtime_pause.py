"""Training under ``real_time=True`` with the world paused during each update.

A real-time world does not wait for the learner: while PPO updates its
networks (tens to hundreds of milliseconds), the sims keep running on the
last action, and the first action after the update acts on a stale
observation seconds late. ``with env.unwrapped.paused():`` around the update
stops every sim's clock instead (physics stops, the held action stays, the
deadlines shift), so the paused time counts in no latency figure.

This trains PPO briefly on 4 real-time continuous CartPole worlds twice,
without and with the pause, and prints the action latency the agent saw
(``env.unwrapped.latency_stats``) and what the pauses cost.

    python examples/latency_realtime_pause.py            # about a minute
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from latency_ppo import _train, make_vec  # the PPO of the delay example


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--budget", type=int, default=4096, help="env steps per run (4 worlds)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    ppo = argparse.Namespace(budget=args.budget, num_envs=4, rollout=64, epochs=6, minibatch=64)
    torch.set_num_threads(1)
    print(f"load average {os.getloadavg()[0]:.2f}")
    for pause in (False, True):
        torch.manual_seed(args.seed)
        env = make_vec(4, False, real_time=True)
        try:
            start = time.perf_counter()
            _, returns = _train(env, args.seed, ppo, "paused updates" if pause else "world runs on", pause)
            wall = time.perf_counter() - start
            stats = env.unwrapped.latency_stats.summary()
            pauser = env.unwrapped.pausing
        finally:
            env.close()
        lat = stats["latency_ticks"]
        print(
            f"{'pause() around updates' if pause else 'no pause':24s}: latency ticks p50 {lat['p50']:.1f} "
            f"p99 {lat['p99']:.1f} max {lat['max']:.1f}; late actions {stats['late_actions']} of {4 * stats['steps']} "
            f"world-steps; {len(returns)} episodes; {pauser.pauses} pauses, {pauser.paused_s:.1f} s paused; {wall:.0f} s wall"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
