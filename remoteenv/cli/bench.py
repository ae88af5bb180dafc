"""``python -m remoteenv bench``: throughput (default), ``--batched`` (batched stepping
next to EnvPool and the physics limit), ``--real-time`` pacing, ``--soak``, ``--sb3``
(SB3 PPO on remote CartPole next to SubprocVecEnv), ``--pixels`` (camera
observations in vector envs next to Gymnasium's of the same in-process task),
``--action-timing`` (real-time steps whose action acted before it was sent),
``--train-loop`` (a PPO-shaped training loop on each vector env, learner on the
same CPUs, next to EnvPool and Gymnasium's)."""

from __future__ import annotations

import argparse
import importlib
from typing import Any

#: Benchmark modules in remoteenv.benchmarks (its entry points; their parts are in
#: remoteenv.benchmarks.harness) and the flag that picks each; the default one first.
BENCHMARKS = {
    "throughput": None,
    "batched": "--batched",
    "pacing": "--real-time",
    "soak": "--soak",
    "sb3_ppo": "--sb3",
    "startup_time": "--startup",
    "pixels": "--pixels",
    "action_timing": "--action-timing",
    "train_loop": "--train-loop",
}


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "bench",
        help="measure remoteenv against in-process Gymnasium",
        description="Benchmarks, each measured side by side in one run on this machine. "
        "Without a mode flag: steps/s of remote envs next to in-process Gymnasium. "
        "--batched: batched stepping next to EnvPool and MuJoCo's physics limit, in alternating rounds. "
        "--real-time: pacing and action-application delay of real-time mode. "
        "--soak: a long run that reports agent and sim memory. "
        "--sb3: SB3 PPO on remote CartPole next to the same PPO on SubprocVecEnv and DummyVecEnv. "
        "--pixels: the camera CartPole's RemoteVectorEnv next to Gymnasium's Async/SyncVectorEnv of the same "
        "task in process (--hog for a CPU hog beside it). "
        "--action-timing: real-time steps whose action acted before it was sent, thinking a third of a tick "
        "and with the sim stopped while the agent thinks, in both regimes. "
        "--train-loop: the envs inside a PPO-shaped training loop, learner on the same CPUs, next to EnvPool and "
        "Gymnasium's Sync/AsyncVectorEnv.",
    )
    mode = p.add_mutually_exclusive_group()
    for name, flag in BENCHMARKS.items():
        if flag:
            mode.add_argument(flag, dest="mode", action="store_const", const=name, help=f"run the {name} benchmark")
    p.set_defaults(mode="throughput", run=run)
    for name in BENCHMARKS:
        try:
            module = importlib.import_module(f"remoteenv.benchmarks.{name}")
        except ModuleNotFoundError:
            continue
        module.add_arguments(p)


def run(args: argparse.Namespace) -> int:
    try:
        module = importlib.import_module(f"remoteenv.benchmarks.{args.mode}")
    except ModuleNotFoundError:
        raise SystemExit(f"benchmark {args.mode!r} is not available in this build") from None
    return int(module.run(args) or 0)
