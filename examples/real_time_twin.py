"""Every real-time run has an exact twin: record it, save it, replay it bit for bit.

Two fixed controllers balance continuous CartPole in real time
(``real_time=True``): the sim runs on the wall clock, and before each action
the agent "thinks" for a random ``U(low, high)`` control ticks of wall time
(20 ms each), with the previous action held meanwhile.

- ``lqr``: the shipped LQR (``remoteenv.controllers.cartpole_continuous``).
- ``predictor``: ``remoteenv.controllers.CartpoleHoldPredictor``: the same
  gains on the state predicted ``--horizon`` ticks ahead with its previous
  action held.

Each regime is run: ``elastic`` (an action takes effect at the next physics
substep; a step lasts until the end of the first tick the action was in
force) and ``fixed_step`` (rtgym's: an action takes effect at the next
control-tick boundary, where the step ends).

``remoteenv.latency.twin.LatencyRecorder`` records, for every step, the
physics substep at which its action took effect; ``save`` writes one episode
per file. ``make_twin(env_id, path)`` replays a file: the sim applies each
action at its recorded substep, without a clock, so the twin of a
deterministic policy repeats the real-time episode bit for bit (every
observation, reward, flag and the step count), however this machine's
timing went. Each episode is reported as identical, or with the first step
at which it differs.

Run:  python examples/real_time_twin.py                       (~1 min: real time takes wall time)
      python examples/real_time_twin.py --episodes 3 --max-steps 40 --json twin.json --recording-dir recordings/
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import remoteenv  # noqa: F401  (registers remoteenv/CartPole-v0)
from remoteenv.controllers import CartpoleHoldPredictor, cartpole_continuous
from remoteenv.latency.twin import ExactTwin, LatencyRecorder, first_difference, load_recording, make_twin

ENV_ID = "remoteenv/CartPole-v0"
ENV_KWARGS = {"continuous": True}


def play(env: gym.Env, policy: Callable[[Any], Any], seed: int, think: Callable[[], None] | None) -> None:
    """One episode from ``reset(seed=seed)``; ``think()`` before each step."""
    obs, _ = env.reset(seed=seed)
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()  # a policy that remembers starts afresh
    done = False
    while not done:
        action = policy(obs)
        if think is not None:
            think()
        obs, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated


def record(policy: Any, mode: str, args: argparse.Namespace, folder: str) -> list[str]:
    """``args.episodes`` real-time episodes, each saved to its own recording file."""
    env = LatencyRecorder(
        gym.make(ENV_ID, real_time=True, real_time_mode=mode, max_episode_steps=args.max_steps, **ENV_KWARGS)
    )
    rng = np.random.default_rng(args.seed)
    tick_s = env.unwrapped.dt  # type: ignore[attr-defined]
    low, high = args.think

    def think() -> None:
        time.sleep(rng.uniform(low, high) * tick_s)

    paths = []
    try:
        for e in range(args.episodes):
            play(env, policy, args.seed + e, think)
            paths.append(env.save(os.path.join(folder, f"episode-{e}.json")))
    finally:
        env.close()
    return paths


def replay(policy: Any, path: str, args: argparse.Namespace) -> dict[str, Any]:
    """Replay one recording file closed loop in its exact twin; compare step by step."""
    episode, _ = load_recording(path)
    twin = make_twin(ENV_ID, path, args.max_steps, **ENV_KWARGS)
    assert isinstance(twin, ExactTwin) and episode.seed is not None
    try:
        # The twin's reset goes to the recorded start (a vector world's episode may
        # need unseeded resets after its seed: twin.reset_to_start() does both).
        play(twin, policy, episode.seed, None)
        # What the twin returned: fingerprints of its observations, its rewards and flags.
        got = {
            "obs_digests": twin.obs_digests,
            "rewards": twin.rewards,
            "terminated": twin.terminated,
            "truncated": twin.truncated,
        }
    finally:
        twin.close()
    diff = first_difference(episode, got)
    return {
        "identical": diff is None,
        "first_difference": diff,
        "steps": episode.steps,
        "ticks": episode.ticks,
        "return": episode.episode_return,
        "twin_return": float(sum(got["rewards"])),
    }


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--think", default="0,3", help="think time range LOW,HIGH in control ticks of wall time")
    parser.add_argument("--episodes", type=int, default=3, help="real-time episodes per controller and regime")
    parser.add_argument("--max-steps", type=int, default=100, help="steps (decisions) per episode at most")
    parser.add_argument("--horizon", type=int, default=3, help="the predictor's horizon (ticks)")
    parser.add_argument("--seed", type=int, default=0, help="episode e resets with seed + e; think times too")
    parser.add_argument("--modes", default="elastic,fixed_step", help="real-time regimes to run")
    parser.add_argument("--recording-dir", default=None, help="keep the recordings here (default: a temp dir)")
    parser.add_argument("--json", default=None, help="write every figure to this JSON file")
    args = parser.parse_args(argv)
    args.think = tuple(float(x) for x in args.think.split(","))
    policies = {"lqr": cartpole_continuous, "predictor": CartpoleHoldPredictor(args.horizon)}
    load_before, started = os.getloadavg(), time.monotonic()
    results: dict[str, dict[str, list[dict[str, Any]]]] = {}
    with tempfile.TemporaryDirectory() as scratch:
        root = args.recording_dir or scratch
        for mode in args.modes.split(","):
            for name, policy in policies.items():
                folder = os.path.join(root, mode, name)
                os.makedirs(folder, exist_ok=True)
                print(f"{mode} {name}: {args.episodes} real-time episodes, think U{args.think} ticks ...", flush=True)
                rows = [replay(policy, path, args) for path in record(policy, mode, args, folder)]
                results.setdefault(mode, {})[name] = rows
                for e, row in enumerate(rows):
                    diff = row["first_difference"]
                    what = "identical" if diff is None else f"first differs at step {diff['step']}: {diff['differs']}"
                    print(
                        f"  episode {e}: {row['steps']} steps, {row['ticks']} ticks, return {row['return']:g}: {what}"
                    )
    rows = [row for by_policy in results.values() for rs in by_policy.values() for row in rs]
    identical = sum(row["identical"] for row in rows)
    steps = sum(row["steps"] for row in rows)
    print(f"\n{identical} of {len(rows)} episodes identical ({steps} steps)")
    print("A return here sums, per step, the reward of every tick the step lasted (CartPole: +1 per tick).")
    report = {
        "env_id": ENV_ID,
        "env_kwargs": ENV_KWARGS,
        "think_ticks": list(args.think),
        "episodes": args.episodes,
        "max_steps": args.max_steps,
        "horizon": args.horizon,
        "seed": args.seed,
        "results": results,
        "identical": identical,
        "total": len(rows),
        "steps": steps,
        "wall_s": time.monotonic() - started,
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
    }
    print(f"{report['wall_s']:.0f} s, load average {load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} after")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    return report


if __name__ == "__main__":
    main()
