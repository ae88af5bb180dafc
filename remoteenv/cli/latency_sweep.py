"""``python -m remoteenv latency-sweep``: a policy's return across delays, over seeds.

For every delay in --delays and every seed in --seeds it runs --episodes
episodes of the env with a fixed policy and records each episode's return
and length. The policy is a builtin controller or a TorchScript file
(--policy), or a plain Python controller (--controller module:function, or
a .py file, optionally file.py:function, default name "policy"): a function
from observation to action, or a class whose no-argument instance is one; a
reset() method, if it has one, is called at each episode's start.
--mode says what a delay of d means:

  action_delay  lock-step, action_delay=d ticks (or, with --random, Uniform(0, d));
  obs_delay     lock-step, obs_delay=d ticks (likewise);
  real_time     real_time=True and the agent thinks d control ticks of wall
                time (d * dt seconds) before each action, so the latency the
                world sees is about d ticks plus the real one (the measured
                mean is reported as latency_ticks).

Lock-step runs repeat exactly: seed ``s`` seeds the first reset of its run
(scene and delay streams), later episodes continue the streams.

It writes ``sweep.csv`` (one row per episode), ``sweep.json`` (the
configuration, the rows and a summary per delay: mean over seeds of each
seed's mean return, with the spread over seeds) and ``sweep.png`` (mean
return against delay, the band spanning the seeds' means) into ``--out``.
In the lock-step modes each row also has the measured mean age of the
action in force (``info["action_delay_ticks"]`` per tick) and how many of
the episode's actions never took effect (overtaken, or still on their way
when it ended); the printed table gives both per delay (mean age per tick,
fraction of the actions sent).

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from remoteenv.cli.arguments import MAX_SEED, json_map, non_negative_int, positive_int
from remoteenv.cli.optional import require
from remoteenv.latency.sweep import (
    BUILTIN_POLICIES,
    MODES,
    SweepEnv,
    SweepFiles,
    load_controller,
    load_policy,
    plot,
    run_sweep,
    summarize,
)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "latency-sweep",
        help="a policy's return across action/observation delays or real-time think times",
        description="\n\n".join(__doc__.split("\n\n")[1:3]) if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("env", help="a Gymnasium id (remoteenv/CartPole-v0), a shipped scene name or a scene script path")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--policy",
        help=f"a builtin controller ({', '.join(BUILTIN_POLICIES)}) or a TorchScript file "
        "(torch.jit.save of a module mapping a float32 obs batch to an action batch)",
    )
    which.add_argument(
        "--controller",
        help="a plain Python controller: module:function (importable, e.g. remoteenv.controllers:cartpole_continuous) "
        "or a .py file (path.py or path.py:function; default function name 'policy'); a class is instantiated "
        "with no arguments",
    )
    p.add_argument("--delays", default="0,1,2,3,4", help="comma-separated delays in control ticks (default 0..4)")
    p.add_argument("--mode", choices=MODES, default="action_delay", help="what a delay means (default action_delay)")
    p.add_argument("--random", action="store_true", help="lock-step: draw each delay from Uniform(0, d) instead")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes per delay and seed (default 5)")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated seeds (default 0,1,2)")
    p.add_argument("--max-steps", type=positive_int, default=None, help="cut episodes at this many steps")
    p.add_argument(
        "--action-history", type=non_negative_int, default=0, help="wrap in ActionHistory(env, k) (the policy's input)"
    )
    p.add_argument("--env-kwargs", default="{}", help="JSON map for the env, e.g. '{\"continuous\": true}'")
    p.add_argument("--out", default="latency-sweep", help="directory for sweep.csv, sweep.json, sweep.png")
    p.add_argument("--no-plot", action="store_true", help="skip the plot (no matplotlib needed)")
    p.set_defaults(run=run)


def int_list(text: str, what: str, maximum: int | None = None) -> list[int]:
    """Comma-separated integers in ``0..maximum`` (one line naming ``what`` if not)."""
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"{what} must be comma-separated integers, got {text[:80]!r}") from None
    if not values or min(values) < 0:
        raise SystemExit(f"{what} must hold at least one integer >= 0, got {text[:80]!r}")
    if maximum is not None and max(values) > maximum:
        raise SystemExit(f"{what} must be integers in 0..{maximum}, got {str(max(values))[:40]}")
    return values


def sweep_env(args: argparse.Namespace) -> SweepEnv:
    """How the sweep makes each point's env, from the command line."""
    return SweepEnv(
        args.env, args.mode, args.random, json_map(args.env_kwargs, "--env-kwargs"), args.max_steps, args.action_history
    )


def make_env(args: argparse.Namespace, delay: int) -> Any:
    """The env of one point of the sweep."""
    return sweep_env(args).make(delay)


def checked_env(args: argparse.Namespace, delay: int) -> Any:
    """:func:`make_env`, its errors about the arguments (an unknown id, keyword
    arguments the scene does not take, a scene that fails to start) one line."""
    import gymnasium as gym

    from remoteenv.agent.errors import RemoteEnvError

    try:
        return make_env(args, delay)
    except (gym.error.Error, ModuleNotFoundError, RemoteEnvError, TypeError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:300]
        raise SystemExit(f"latency-sweep: cannot make {args.env[:200]!r}: {first}") from None


def run(args: argparse.Namespace) -> int:
    from remoteenv.delays import MAX_DELAY_TICKS

    delays = int_list(args.delays, "--delays", MAX_DELAY_TICKS)
    seeds = int_list(args.seeds, "--seeds", MAX_SEED)
    if args.action_history > MAX_DELAY_TICKS:
        raise SystemExit(f"--action-history must be within 0..{MAX_DELAY_TICKS} (the most actions in flight)")
    if args.action_history and args.policy in BUILTIN_POLICIES:
        raise SystemExit(
            "--action-history changes the observation; the builtin controllers take the env's own: "
            "use it with a TorchScript --policy or a --controller"
        )
    if args.episodes < 1:
        raise SystemExit("--episodes must be >= 1")
    if args.max_steps is not None and args.max_steps < 1:
        raise SystemExit("--max-steps must be a positive integer")
    if args.random and args.mode == "real_time":
        raise SystemExit("--random applies to the lock-step modes; real_time's think time is fixed per point")
    json_map(args.env_kwargs, "--env-kwargs")
    if not args.no_plot:
        require("matplotlib", "latency-sweep's plot (or pass --no-plot)")
    if args.policy is not None and args.policy not in BUILTIN_POLICIES and os.path.isfile(args.policy):
        require("torch", "a TorchScript --policy")
    policy = load_policy(args.policy) if args.policy is not None else load_controller(args.controller)
    files = SweepFiles(args.out)  # before the first sim starts
    config = {k: v for k, v in vars(args).items() if k != "run"}
    rows, wall = run_sweep(
        lambda d: checked_env(args, d), policy, delays, seeds, args.episodes, args.mode, files, config
    )
    summary = summarize(rows, delays, seeds)
    kind = f"Uniform(0, d) {args.mode}" if args.random else args.mode
    xlabel = "think time d (ticks)" if args.mode == "real_time" else f"{kind} d (ticks)"
    if not args.no_plot:
        plot(
            summary,
            os.path.join(args.out, "sweep.png"),
            f"{args.env}, {args.policy or args.controller}: {kind}",
            xlabel,
        )
    print(
        f"{'delay':>5}  {'mean return':>11}  {'std (seeds)':>11}  {'latency ticks':>13}  "
        f"{'action age':>10}  {'never acted':>11}"
    )
    for point in summary:
        age, never = point["mean_action_age_ticks"], point["never_acted_fraction"]
        print(
            f"{point['delay']:5d}  {point['mean_return']:11.2f}  {point['std_over_seeds']:11.2f}  "
            f"{point['mean_latency_ticks']:13.2f}  {'-' if age is None else f'{age:10.2f}':>10}  "
            f"{'-' if never is None else f'{never:11.3f}':>11}"
        )
    print(f"wrote {files.csv_path}, sweep.json{'' if args.no_plot else ', sweep.png'} in {wall:.1f} s")
    return 0
