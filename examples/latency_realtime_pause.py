"""Training under ``real_time=True`` with the world paused during each update.

A real-time world does not wait for the learner: while PPO updates its
networks (tens to hundreds of milliseconds), the sims keep running on the
last action, and the first action after the update acts on an observation
as old as the update took. ``env.pause()`` before the update and
``env.resume()`` after it stop every sim's clock instead (physics stops, the
held action stays, the deadlines shift), so the paused time counts in no
latency figure.

This trains Stable-Baselines3 PPO briefly on 4 real-time continuous CartPole
worlds twice, without and with the pause (an SB3 callback: pause when a
rollout ends, resume when the next one starts), and prints the action
latency the agent saw (``latency_stats``) and what the pauses cost.

    python examples/latency_realtime_pause.py            # about a minute

Needs torch and stable-baselines3 (``pip install 'remoteenv[torch,sb3]'``).
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

import remoteenv  # noqa: F401  (registers remoteenv/CartPole-v0)
from remoteenv import RemoteVectorEnv
from remoteenv.integrations.sb3 import SB3VecEnv


class PauseDuringUpdates(BaseCallback):
    """Pause the real-time worlds while PPO updates; resume before the next rollout."""

    def __init__(self, worlds: RemoteVectorEnv) -> None:
        super().__init__()
        self.worlds = worlds

    def _on_rollout_start(self) -> None:
        self.worlds.resume()

    def _on_rollout_end(self) -> None:
        self.worlds.pause()

    def _on_step(self) -> bool:
        return True


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--budget", type=int, default=4096, help="env steps per run, over the 4 worlds")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    torch.set_num_threads(1)
    print(f"load average {os.getloadavg()[0]:.2f}")
    for pause in (False, True):
        venv = SB3VecEnv(
            gym.make_vec(
                "remoteenv/CartPole-v0", 4, vectorization_mode="vector_entry_point", continuous=True, real_time=True
            )
        )
        worlds = venv.venv.unwrapped
        try:
            model = PPO("MlpPolicy", venv, n_steps=128, batch_size=64, n_epochs=6, seed=args.seed, device="cpu")
            start = time.perf_counter()
            model.learn(args.budget, callback=PauseDuringUpdates(worlds) if pause else None)
            wall = time.perf_counter() - start
            worlds.resume()
            stats = worlds.latency_stats.summary()
            pauser = worlds.pausing
        finally:
            venv.close()
        lat = stats["latency_ticks"]
        print(
            f"{'pause() during updates' if pause else 'no pause':24s}: latency ticks p50 {lat['p50']:.1f} "
            f"p99 {lat['p99']:.1f} max {lat['max']:.1f}; late actions {stats['late_actions']} of "
            f"{4 * stats['steps']} world-steps; {pauser.pauses} pauses, {pauser.paused_s:.1f} s paused; {wall:.0f} s wall"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
