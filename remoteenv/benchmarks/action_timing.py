"""``python -m remoteenv bench --action-timing``: does any real-time action act before it was sent?

Runs in the agent process (it starts one real-time sim per regime). Two
measurements, both regimes (``elastic`` and ``fixed_step``), continuous
CartPole balanced by the LQR controller:

- **Steady**: ``--at-steps`` steps (default 500) in which the agent thinks a
  fraction of a tick (``--at-think``, default 1/3) after each reply. Per
  step the agent notes the wall time it sent the action (``time.monotonic``,
  the sim's clock too on Linux) and the time its reply came. A step *acted
  before it was sent* when the deadline of the substep where its action took
  effect (``t0 + action_substep * period``) precedes the send. The agent does
  not know ``t0`` (the moment the episode's clock started), but every reply
  bounds it from above: a reply about substep ``n`` is sent when boundary
  ``n`` is processed, never before its deadline, so ``t0 <= received -
  n * period``; the smallest bound over the episode's replies is used. A
  step counted is therefore certainly early (by at least the margin
  printed); a violation smaller than the best reply's transit time is
  missed. Also counted: steps whose reported latency is below the agent's
  think time (from receiving the previous reply to sending).
- **Stalled**: the agent stops its own sim (``SIGSTOP`` of the sim process
  the env launched) right after a reply, thinks ``--at-stall-think-ms``
  (default 25), sends, and the sim is continued (``SIGCONT``) once
  ``--at-stall-ms`` (default 60) have passed since the reply. Printed per
  trial: the step's ``ticks_elapsed``, ``latency_ticks`` and ``late``. An
  action sent during a stall cannot act before the stall ends, so the
  latency should be at least the stall.

``--at-hog N`` runs ``N`` CPU-bound processes beside it. It measures and
prints (``--json PATH`` or ``-`` for the figures as JSON); it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import signal
import threading
import time
from typing import Any

import gymnasium as gym

from remoteenv.benchmarks.harness.report import emit, machine_record, progress_log
from remoteenv.benchmarks.pacing import start_hogs, stop_hogs
from remoteenv.scene_controllers.cartpole import cartpole_continuous
from remoteenv.wire.run_options.real_time_modes import REAL_TIME_MODES

ENV_ID = "remoteenv/CartPole-v0"
MODES = REAL_TIME_MODES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("action timing benchmark (--action-timing)")
    g.add_argument("--at-steps", type=int, default=500, help="steps per regime in the steady run (default 500)")
    g.add_argument(
        "--at-think", type=float, default=1 / 3, help="the agent thinks this many ticks per step (default 1/3)"
    )
    g.add_argument("--at-stall-ms", type=float, default=60.0, help="wall ms the sim is stopped per trial (default 60)")
    g.add_argument(
        "--at-stall-think-ms", type=float, default=25.0, help="wall ms the agent thinks while stopped (default 25)"
    )
    g.add_argument("--at-stall-trials", type=int, default=5, help="stalled steps per regime (default 5)")
    g.add_argument("--at-hog", type=int, default=0, help="run this many CPU-bound processes beside the benchmark")
    g.add_argument("--at-seed", type=int, default=0, help="reset seed (default 0)")


def _sleep_until(t: float) -> None:
    while (left := t - time.monotonic()) > 0:
        time.sleep(left)


def steady(mode: str, steps: int, think_ticks: float, seed: int) -> dict[str, Any]:
    """``steps`` steps thinking ``think_ticks`` ticks each; the counts of the module docs."""
    env = gym.make(ENV_ID, continuous=True, real_time=True, real_time_mode=mode, max_episode_steps=-1)
    try:
        remote: Any = env.unwrapped
        dt = float(remote.dt)
        frame_skip = int(remote.handshake.frame_skip)
        period = dt / frame_skip  # real_time_factor 1
        episodes: list[list[dict[str, float]]] = []
        obs, _ = env.reset(seed=seed)
        received = time.monotonic()
        rows: list[dict[str, float]] = []
        for _ in range(steps):
            action = cartpole_continuous(obs)
            _sleep_until(received + think_ticks * dt)
            sent = time.monotonic()
            obs, _, terminated, truncated, info = env.step(action)
            now = time.monotonic()
            applied = info["action_substep"]
            rows.append(
                {
                    "sent": sent,
                    "think": sent - received,
                    "received": now,
                    "substep": float(info["substep"]),
                    "action_substep": -1.0 if applied is None else float(applied),
                    "latency_s": -1.0 if info["latency_s"] is None else float(info["latency_s"]),
                    "ticks": float(info["ticks_elapsed"]),
                }
            )
            received = now
            if terminated or truncated:
                episodes.append(rows)
                rows = []
                obs, _ = env.reset()
                received = time.monotonic()
        if rows:
            episodes.append(rows)
    finally:
        env.close()
    early, below_think, margins = 0, 0, []
    for rows in episodes:
        t0_bound = min(r["received"] - r["substep"] * period for r in rows)
        for r in rows:
            if r["action_substep"] < 0:
                continue
            margin = r["sent"] - (t0_bound + r["action_substep"] * period)
            if margin > 0:
                early += 1
                margins.append(margin)
            if r["latency_s"] < r["think"]:
                below_think += 1
    all_rows = [r for rows in episodes for r in rows]
    return {
        "mode": mode,
        "steps": len(all_rows),
        "episodes": len(episodes),
        "acted_before_sent": early,
        "early_by_ms_max": 1e3 * max(margins, default=0.0),
        "latency_below_think": below_think,
        "late_steps": sum(r["ticks"] > 1 for r in all_rows),
    }


def stalled(mode: str, trials: int, stall_s: float, think_s: float, seed: int) -> list[dict[str, Any]]:
    """``trials`` steps, each with the sim stopped ``stall_s`` from the reply while the agent thinks ``think_s``."""
    env = gym.make(ENV_ID, continuous=True, real_time=True, real_time_mode=mode, max_episode_steps=-1)
    out = []
    try:
        pid = env.unwrapped.pid  # type: ignore[attr-defined]
        obs, _ = env.reset(seed=seed)
        for _ in range(5):  # settle
            obs, *_ = env.step(cartpole_continuous(obs))
        for _ in range(trials):
            received = time.monotonic()
            os.kill(pid, signal.SIGSTOP)
            resume = threading.Timer(max(0.0, received + stall_s - time.monotonic()), os.kill, (pid, signal.SIGCONT))
            resume.start()
            try:
                action = cartpole_continuous(obs)
                _sleep_until(received + think_s)
                obs, _, terminated, truncated, info = env.step(action)
            finally:
                resume.join()
                os.kill(pid, signal.SIGCONT)
            out.append(
                {
                    "ticks_elapsed": info["ticks_elapsed"],
                    "latency_ticks": info["latency_ticks"],
                    "late": info["late"],
                }
            )
            if terminated or truncated:
                obs, _ = env.reset()
            for _ in range(3):  # back in step before the next trial
                obs, *_ = env.step(cartpole_continuous(obs))
    finally:
        env.close()
    return out


def run(args: argparse.Namespace) -> int:
    log = progress_log(args.json)
    hogs = start_hogs(args.at_hog)
    try:
        result: dict[str, Any] = {
            "machine": machine_record(),
            "hogs": args.at_hog,
            "load_before": os.getloadavg()[0],
            "think_ticks": args.at_think,
            "stall_ms": args.at_stall_ms,
            "stall_think_ms": args.at_stall_think_ms,
            "steady": [],
            "stalled": {},
        }
        for mode in MODES:
            log(f"{mode}: {args.at_steps} steps thinking {args.at_think:.3g} tick ...")
            result["steady"].append(steady(mode, args.at_steps, args.at_think, args.at_seed))
        for mode in MODES:
            log(f"{mode}: {args.at_stall_trials} stalled steps ...")
            result["stalled"][mode] = stalled(
                mode, args.at_stall_trials, args.at_stall_ms / 1e3, args.at_stall_think_ms / 1e3, args.at_seed
            )
        result["load_after"] = os.getloadavg()[0]
    finally:
        stop_hogs(hogs)
    emit(result, args.json, format_table)
    return 0


def format_table(r: dict[str, Any]) -> str:
    lines = [
        f"action timing: continuous CartPole, real_time_factor 1, {r['hogs']} CPU hog(s), "
        f"load average {r['load_before']:.2f} before / {r['load_after']:.2f} after",
        f"steady: thinking {r['think_ticks']:.3g} tick per step",
        f"{'regime':10s} {'steps':>5s} {'acted before sent':>17s} {'by up to ms':>11s} "
        f"{'latency < think':>15s} {'late':>5s}",
    ]
    for s in r["steady"]:
        lines.append(
            f"{s['mode']:10s} {s['steps']:5d} {s['acted_before_sent']:17d} {s['early_by_ms_max']:11.3f} "
            f"{s['latency_below_think']:15d} {s['late_steps']:5d}"
        )
    lines.append(f"stalled: sim stopped {r['stall_ms']:g} ms from the reply, agent thinks {r['stall_think_ms']:g} ms")
    for mode, trials in r["stalled"].items():
        cells = ", ".join(
            f"{t['ticks_elapsed']} tick(s) latency {t['latency_ticks']:g} late {t['late']}" for t in trials
        )
        lines.append(f"{mode:10s} {cells}")
    return "\n".join(lines)


__all__ = ["add_arguments", "run", "stalled", "steady"]
