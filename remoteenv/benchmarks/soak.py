"""``python -m remoteenv bench --soak``: a long run that watches memory.

Drives one remote env for ``--soak-steps`` steps (1,000,000 by default) with
seeded random actions, resetting whenever an episode ends, and prints the
resident set size (RSS, from ``/proc/<pid>/status``) of the agent process and
of the sim process: after launch, after a warm-up, at every tenth of the run
and at the end. Growth is reported against the warm-up figures (the first
steps allocate caches once). It measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from typing import Any, cast

import numpy as np

from remoteenv import SHIPPED_SCENES as SCENES


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("soak (--soak)")
    g.add_argument("--soak-steps", type=int, default=1_000_000, help="steps to run (default 1,000,000)")
    g.add_argument(
        "--soak-warmup", type=int, default=10_000, help="steps before the baseline RSS is taken (default 10,000)"
    )
    g.add_argument(
        "--soak-scene", choices=sorted(SCENES), default="cartpole", help="which shipped scene (default cartpole)"
    )
    g.add_argument(
        "--soak-transport",
        choices=["pipe", "ipc", "tcp"],
        default="pipe",
        help="how the env talks to its sim (default pipe, the env's default)",
    )
    g.add_argument("--soak-seed", type=int, default=0, help="seed of actions and resets")


def rss_kib(pid: int) -> int | None:
    """Resident set size of ``pid`` in KiB (Linux /proc), or None if unknown."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _mib(kib: int | None) -> str:
    return "?" if kib is None else f"{kib / 1024:.1f} MiB"


def _growth(start: int | None, end: int | None) -> str:
    if not start or end is None:
        return "?"
    return f"{100.0 * (end - start) / start:+.2f}%"


def run(args: argparse.Namespace) -> int:
    import gymnasium as gym

    steps, warmup = int(args.soak_steps), max(0, int(args.soak_warmup))
    env = gym.make(SCENES[args.soak_scene], transport=args.soak_transport, disable_env_checker=True)
    try:
        agent_pid, sim_pid = os.getpid(), cast(Any, env.unwrapped).pid
        assert sim_pid is not None
        print(
            f"soak: {steps:,} steps of {SCENES[args.soak_scene]} over {args.soak_transport}, "
            f"random actions; {os.cpu_count()} CPUs, {platform.machine()}, "
            f"Python {platform.python_version()}, {platform.platform()}"
        )
        print(f"after launch:   agent RSS {_mib(rss_kib(agent_pid))}, sim RSS {_mib(rss_kib(sim_pid))}")
        rng = np.random.default_rng(args.soak_seed)
        env.action_space.seed(args.soak_seed)
        env.reset(seed=args.soak_seed)
        episodes = 0

        def drive(n: int) -> None:
            nonlocal episodes
            for _ in range(n):
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                if terminated or truncated:
                    episodes += 1
                    env.reset(seed=int(rng.integers(2**31)))

        drive(min(warmup, steps))
        base: dict[str, Any] = {"agent": rss_kib(agent_pid), "sim": rss_kib(sim_pid)}
        print(
            f"after {min(warmup, steps):,} warm-up steps: agent RSS {_mib(base['agent'])}, "
            f"sim RSS {_mib(base['sim'])}  (baseline)"
        )
        remaining = steps - min(warmup, steps)
        chunk = max(1, remaining // 10)
        done, start = 0, time.perf_counter()
        while done < remaining:
            n = min(chunk, remaining - done)
            drive(n)
            done += n
            elapsed = time.perf_counter() - start
            agent, sim = rss_kib(agent_pid), rss_kib(sim_pid)
            print(
                f"{done + min(warmup, steps):>10,} steps  {done / elapsed:8.0f} steps/s  "
                f"agent RSS {_mib(agent)} ({_growth(base['agent'], agent)})  "
                f"sim RSS {_mib(sim)} ({_growth(base['sim'], sim)})",
                flush=True,
            )
        end = {"agent": rss_kib(agent_pid), "sim": rss_kib(sim_pid)}
        elapsed = time.perf_counter() - start
        print(
            f"end: {steps:,} steps, {episodes:,} episodes, {elapsed:.1f} s after warm-up "
            f"({done / elapsed if elapsed else 0:.0f} steps/s)"
        )
        print(
            f"agent RSS {_mib(base['agent'])} -> {_mib(end['agent'])} "
            f"({_growth(base['agent'], end['agent'])}); "
            f"sim RSS {_mib(base['sim'])} -> {_mib(end['sim'])} ({_growth(base['sim'], end['sim'])})"
        )
    finally:
        env.close()
    return 0
