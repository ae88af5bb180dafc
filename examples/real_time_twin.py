"""Every real-time run has a reproducible twin: record it, replay it in lock-step, compare.

Two fixed controllers balance continuous CartPole in real time
(``real_time=True``): the sim runs on the wall clock, and before each action
the agent "thinks" for a random ``U(low, high)`` control ticks of wall time
(20 ms each), with the previous action held meanwhile. So every step is
elastic: it lasts as many ticks as the agent took.

- ``lqr``: the shipped LQR (``remoteenv.controllers.cartpole_continuous``).
- ``predictor``: ``remoteenv.controllers.CartpoleHoldPredictor``: the same
  gains on the state predicted ``--horizon`` ticks ahead with its previous
  action held (the delay-aware controller of examples/delay_aware_controller.py,
  for an agent that acts once per elastic step).

``remoteenv.latency_twin`` records each real-time episode's latencies as a
``Trace`` (one action delay per tick), replays it in lock-step with
``action_delay=Trace(...)`` and the same policy, and compares the returns
episode by episode (same reset seed, same latencies). The replay is exact
and repeats bit for bit; the real-time run is whatever this machine did.
Each recording is replayed twice, once per way of turning a latency into
whole ticks: ``nearest`` (the default) and ``floor`` (which applies every
action up to a tick early, and shows what a biased twin looks like).

Run:  python examples/real_time_twin.py                       (~4 min: real time takes wall time)
      python examples/real_time_twin.py --episodes 3 --max-steps 40 --json twin.json --trace-dir traces/
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Sequence
from typing import Any

import remoteenv  # noqa: F401  (registers remoteenv/CartPole-v0)
from remoteenv.controllers import CartpoleHoldPredictor, cartpole_continuous
from remoteenv.latency_twin import compare_recorded, run_real_time, save_episode

ENV_ID = "remoteenv/CartPole-v0"
ENV_KWARGS = {"continuous": True}


def row(policy: str, result: dict[str, Any]) -> str:
    """One line of the table for one policy and one rounding."""
    c, t, e = result["comparison"], result["traces"], result["endings"]
    rt, rp = result["real_time"]["returns"], result["replay"]["returns"]
    return (
        f"{policy:<10} {result['rounding']:<8} {c['real_time_mean']:7.1f} ({min(rt):.0f}-{max(rt):.0f})"
        f" {c['replay_mean']:7.1f} ({min(rp):.0f}-{max(rp):.0f})"
        f" {c['mean_difference']:+7.1f} [{c['ci'][0]:+6.1f}, {c['ci'][1]:+6.1f}] +-{c['tolerance']:5.1f}"
        f"  {c['verdict']:<12} {c['ks_distance']:.2f}  {e['same_termination']}/{c['episodes']}"
        f"  {t['mean_latency_ticks']:.2f}/{t['mean_twin_latency_ticks']:.2f}"
    )


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--think", default="0,6", help="think time range LOW,HIGH in control ticks of wall time")
    parser.add_argument("--episodes", type=int, default=10, help="real-time episodes per controller")
    parser.add_argument("--max-steps", type=int, default=200, help="steps (decisions) per episode at most")
    parser.add_argument("--horizon", type=int, default=3, help="the predictor's horizon (ticks)")
    parser.add_argument("--seed", type=int, default=0, help="episode e resets with seed + e; think times too")
    parser.add_argument("--roundings", default="nearest,floor", help="latency roundings to replay with")
    parser.add_argument("--trace-dir", default=None, help="save every episode's trace (nearest) here")
    parser.add_argument("--json", default=None, help="write every figure to this JSON file")
    args = parser.parse_args(argv)
    low, high = (float(x) for x in args.think.split(","))
    policies = {"lqr": cartpole_continuous, "predictor": CartpoleHoldPredictor(args.horizon)}
    load_before, started = os.getloadavg(), time.monotonic()
    results: dict[str, dict[str, Any]] = {}
    for name, policy in policies.items():
        print(f"{name}: {args.episodes} real-time episodes, think U({low:g}, {high:g}) ticks ...", flush=True)
        recorded = run_real_time(
            policy,
            ENV_ID,
            ENV_KWARGS,
            think_ticks=(low, high),
            episodes=args.episodes,
            seed=args.seed,
            max_episode_steps=args.max_steps,
        )
        if args.trace_dir:
            folder = os.path.join(args.trace_dir, name)
            os.makedirs(folder, exist_ok=True)
            for e, episode in enumerate(recorded):
                save_episode(episode, os.path.join(folder, f"episode-{e}.trace.txt"), ENV_ID)
        results[name] = {
            rounding: compare_recorded(
                policy, ENV_ID, recorded, ENV_KWARGS, max_episode_steps=args.max_steps, rounding=rounding
            )
            for rounding in args.roundings.split(",")
        }
    print(
        "\npolicy     rounding real time (range)  replay (range)    diff [95% CI]      tolerance"
        "  verdict      KS    same end  latency real/twin (ticks)"
    )
    for name, by_rounding in results.items():
        for result in by_rounding.values():
            print(row(name, result))
    report = {
        "env_id": ENV_ID,
        "env_kwargs": ENV_KWARGS,
        "think_ticks": [low, high],
        "episodes": args.episodes,
        "max_steps": args.max_steps,
        "horizon": args.horizon,
        "seed": args.seed,
        "results": results,
        "wall_s": time.monotonic() - started,
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
    }
    print(f"\n{report['wall_s']:.0f} s, load average {load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} after")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    return report


if __name__ == "__main__":
    main()
