"""``python -m remoteenv bench --pixels``: camera observations in vector envs.

Agent side; it launches sims. The camera CartPole (``obs_mode="pixels"``,
uint8 images rendered by MuJoCo's offscreen renderer, without MSAA and
shadows) stepped as ``RemoteVectorEnv`` (its default layout, and the splits
given with ``--pixels-k``) next to Gymnasium's ``AsyncVectorEnv`` and
``SyncVectorEnv`` of the same task written as an in-process env
(:mod:`remoteenv.benchmarks.harness.in_process`: the same MJCF, hooks and renderer
settings), at each ``--pixels-cases`` (image side x worlds; default 64x8,
84x8, 64x16). Per case the contenders are built, then timed in
``--pixels-rounds`` alternating rounds of ``--pixels-duration`` s, so load
that comes and goes hits them alike; medians and ratios are printed, and the
layout the default chose. ``--hog`` runs CPU hogs beside it; ``--json PATH``
also writes the results. First it prints the milliseconds per 64x64 frame at
each render quality (:mod:`remoteenv.benchmarks.render_cost`). It measures
and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import statistics
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from remoteenv import RemoteVectorEnv
from remoteenv.benchmarks.batched import Contender
from remoteenv.benchmarks.harness.anchors import CpuHog
from remoteenv.benchmarks.harness.in_process import make_in_process
from remoteenv.benchmarks.harness.report import emit, machine_record, progress_log
from remoteenv.benchmarks.render_cost import format_cost, render_cost
from remoteenv.sim.scene.cameras import MAX_SIDE
from remoteenv.wire.codec.frame_limits import MAX_MESSAGE_BYTES
from remoteenv.wire.memory import format_bytes, resident_bytes, worlds_problem

REMOTE_ID = "remoteenv/CartPole-v0"
#: The scene script of ``--pixels-render-in-hook``.
HOOK_RENDER_SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "harness", "hook_render_scene.py")
#: (image side, worlds) measured by default; the first is the one with targets.
DEFAULT_CASES = "64x8,84x8,64x16"
#: (ratio, numerator, denominator, target at the first case)
TARGETS = [
    ("RemoteVectorEnv / AsyncVectorEnv", "RemoteVectorEnv", "AsyncVectorEnv", 1.5),
    ("RemoteVectorEnv / SyncVectorEnv", "RemoteVectorEnv", "SyncVectorEnv", 1.2),
]
#: The same with ``--pixels-render-in-hook``: the default layout, chosen from a
#: measured whole step, must beat AsyncVectorEnv as a declared camera's does.
HOOK_TARGETS = [
    ("RemoteVectorEnv / AsyncVectorEnv", "RemoteVectorEnv", "AsyncVectorEnv", 1.2),
    ("RemoteVectorEnv / SyncVectorEnv", "RemoteVectorEnv", "SyncVectorEnv", None),
]


#: Longest ``--pixels-duration`` (seconds per contender per round).
MAX_DURATION_S = 600.0
#: Most ``--pixels-rounds``.
MAX_ROUNDS = 100


def _duration(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0 < value <= MAX_DURATION_S):
        raise argparse.ArgumentTypeError(f"must be seconds in (0, {MAX_DURATION_S:g}], got {text[:40]!r}")
    return value


def _rounds(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= MAX_ROUNDS:
        raise argparse.ArgumentTypeError(f"must be an int in 1..{MAX_ROUNDS}, got {text[:40]!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("pixels benchmark (--pixels)")
    g.add_argument(
        "--pixels-cases",
        default=DEFAULT_CASES,
        help=f"comma-separated SIDExWORLDS cases (default {DEFAULT_CASES}; targets at the first)",
    )
    g.add_argument(
        "--pixels-duration",
        type=_duration,
        default=1.0,
        help=f"seconds per contender per round, at most {MAX_DURATION_S:g} (default 1)",
    )
    g.add_argument(
        "--pixels-rounds",
        type=_rounds,
        default=3,
        help=f"alternating rounds, at most {MAX_ROUNDS}; medians shown (default 3)",
    )
    g.add_argument(
        "--pixels-render-in-hook",
        action="store_true",
        help="every contender's scene renders its image in its own hook, no camera declared "
        "(remoteenv.benchmarks.harness.hook_render_scene): the layout must see the cost by measuring a whole step",
    )
    g.add_argument(
        "--pixels-k",
        default="",
        help="also time RemoteVectorEnv with these envs_per_process, comma-separated (default: only the default layout)",
    )


def parse_cases(text: str) -> list[tuple[int, int]]:
    """``"64x8,84x8"`` -> ``[(64, 8), (84, 8)]``; exits with a message on anything else:
    a side above what a camera declares or one frame beyond what a reply carries."""
    cases = []
    largest = max_side()
    for part in text.split(",")[:64]:
        side, _, worlds = part.strip().partition("x")
        try:
            case = (int(side), int(worlds))
        except ValueError:
            raise SystemExit(f"--pixels-cases must be SIDExWORLDS items like 64x8, got {part[:40]!r}") from None
        if min(case) < 1:
            raise SystemExit(f"--pixels-cases needs positive sides and worlds, got {part[:40]!r}")
        if case[0] > largest:
            raise SystemExit(
                f"--pixels-cases {part.strip()[:40]}: a {case[0]}x{case[0]} image is beyond the largest a "
                f"camera world sends ({largest}x{largest}: {MAX_SIDE} px per side, one frame per reply); "
                f"use a side up to {largest}"
            )
        cases.append(case)
    return cases


def max_side() -> int:
    """The largest square RGB image side a camera declares and one reply carries."""
    return min(MAX_SIDE, math.isqrt(MAX_MESSAGE_BYTES // 3))


def world_footprint(side: int) -> tuple[int, int] | None:
    """``(bytes, interpreter bytes)``: what one more in-process camera world of
    ``side`` pixels costs this process (its resident set grown by building and
    rendering it, measured on the second of two), and this process's resident
    set before (about what an ``AsyncVectorEnv`` worker costs besides its
    world); None where it cannot be read."""
    base = resident_bytes()
    envs = [make_in_process("cartpole", None, obs_mode="pixels", image_size=side)]
    try:
        envs[0].reset(seed=0)
        before = resident_bytes()
        envs.append(make_in_process("cartpole", None, obs_mode="pixels", image_size=side))
        envs[1].reset(seed=0)
        after = resident_bytes()
    finally:
        for env in envs:
            env.close()
    if base is None or before is None or after is None:
        return None
    return max(after - before, 1), base


def check_memory(cases: list[tuple[int, int]], footprint: Callable[[int], tuple[int, int] | None]) -> None:
    """Exit with one line, before anything is built, for a case whose three
    contenders would not fit in the memory this machine has available: each
    world is held three times (in process for SyncVectorEnv, in an
    ``AsyncVectorEnv`` worker with its interpreter, in a sim for
    RemoteVectorEnv), at ``footprint(side)`` as measured here."""
    measured: dict[int, tuple[int, int] | None] = {}
    for side, n in cases:
        if side not in measured:
            measured[side] = footprint(side)
        figures = measured[side]
        if figures is None:
            continue
        world, interpreter = figures
        problem = worlds_problem(
            n,
            3 * world + interpreter,
            f"--pixels-cases {side}x{n}",
            "ask for at most {fit} worlds at this side (measured here: "
            + f"{format_bytes(world)} a world, {format_bytes(interpreter)} an AsyncVectorEnv worker's interpreter)",
        )
        if problem is not None:
            raise SystemExit(problem)


def _actions(n: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [rng.integers(0, 2, size=n) for _ in range(64)]


def _contender(name: str, env: Any) -> Contender:
    n = env.num_envs
    actions = _actions(n)
    env.reset(seed=0)
    return Contender(name, n, env, lambda i: env.step(actions[i & 63]), n)


def contenders(side: int, n: int, ks: list[int], in_hook: bool = False) -> list[Contender]:
    """The contenders of one case (built; the caller closes them). ``in_hook``:
    the scene renders its image in its own hook (:mod:`remoteenv.benchmarks.harness.hook_render_scene`)."""
    import remoteenv  # noqa: F401  (registers the ids)

    limit = gym.spec(REMOTE_ID).max_episode_steps
    kwargs: dict[str, Any] = {"image_size": side} if in_hook else {"obs_mode": "pixels", "image_size": side}
    scene = HOOK_RENDER_SCENE if in_hook else "cartpole"
    make = functools.partial(make_in_process, scene, limit, **kwargs)

    def remote(**more: Any) -> Any:
        if in_hook:
            return RemoteVectorEnv(HOOK_RENDER_SCENE, n, max_episode_steps=limit, **kwargs, **more)
        return gym.make_vec(REMOTE_ID, num_envs=n, vectorization_mode="vector_entry_point", **kwargs, **more)

    built = []
    try:
        built.append(_contender("SyncVectorEnv", gym.vector.SyncVectorEnv([make] * n)))
        # spawn: a forked worker would inherit this process's EGL state (the render
        # cost and SyncVectorEnv's renderers) and hang in its first render.
        built.append(_contender("AsyncVectorEnv", gym.vector.AsyncVectorEnv([make] * n, context="spawn")))
        built.append(_contender("RemoteVectorEnv", remote()))
        for k in ks:
            built.append(_contender(f"RemoteVectorEnv K={k}", remote(envs_per_process=k)))
    except BaseException:
        for c in built:
            c.close()
        raise
    return built


def measure(
    cases: list[tuple[int, int]],
    duration: float,
    rounds: int,
    hog: int,
    ks: list[int],
    log: Callable[[str], None] = print,
    in_hook: bool = False,
) -> dict[str, Any]:
    """Every case's contenders in alternating rounds; ``{"render_cost_ms", "rows", "ratios", ...}``."""
    log("render cost (this process, no sims):")
    costs = render_cost(64, rounds=3, frames=5)
    log(format_cost(costs, 64))
    rows: list[dict[str, Any]] = []
    with CpuHog(hog) as hogs:
        for side, n in cases:
            log(f"{side}x{side} pixels, N={n}: building ...")
            built = contenders(side, n, ks, in_hook)
            try:
                remote = next(c for c in built if c.name == "RemoteVectorEnv")
                k = int(remote.env.envs_per_process)
                for c in built:
                    c.measure(min(0.2, duration), hogs.pids)  # warm-up
                    c.rates.clear()
                    c.cpu_us.clear()
                for r in range(rounds):
                    for c in built:
                        c.measure(duration, hogs.pids)
                    log(f"  round {r + 1}: " + ", ".join(f"{c.name} {c.rates[-1]:.0f}" for c in built))
                for c in built:
                    rows.append(
                        {
                            "side": side,
                            "num_envs": n,
                            "name": c.name,
                            "envs_per_process": k if c.name == "RemoteVectorEnv" else None,
                            "steps_per_s": statistics.median(c.rates),
                            "rates": c.rates,
                            "cpu_us_per_step": statistics.median(c.cpu_us),
                        }
                    )
            finally:
                for c in built:
                    c.close()
    return {
        "machine": {
            **machine_record(),
            "load_avg_at_end": list(os.getloadavg()),
            "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"),
        },
        "duration_s": duration,
        "rounds": rounds,
        "hogs": hog,
        "render_in_hook": in_hook,
        "render_cost_ms": costs,
        "rows": rows,
        "ratios": ratios(rows, cases[0] if cases else None, in_hook),
    }


def ratios(rows: list[dict[str, Any]], targeted: tuple[int, int] | None, in_hook: bool = False) -> list[dict[str, Any]]:
    """RemoteVectorEnv over Async and Sync per case (targets at ``targeted``;
    :data:`HOOK_TARGETS` when the scene renders in its hook)."""

    def rate(side: int, n: int, name: str) -> float | None:
        return next((r["steps_per_s"] for r in rows if (r["side"], r["num_envs"], r["name"]) == (side, n, name)), None)

    out = []
    for side, n in sorted({(r["side"], r["num_envs"]) for r in rows}, key=lambda c: (c[1], c[0])):
        for what, num, den, target in HOOK_TARGETS if in_hook else TARGETS:
            a, b = rate(side, n, num), rate(side, n, den)
            if a and b:
                out.append(
                    {
                        "case": f"{side}x{side} N={n}",
                        "ratio": what,
                        "value": a / b,
                        "target": target if (side, n) == targeted else None,
                    }
                )
    return out


def format_table(result: dict[str, Any]) -> str:
    lines = [format_cost(result["render_cost_ms"], 64), ""]
    lines.append(f"{'case':14s} {'contender':24s} {'K':>3s} {'steps/s':>9s} {'CPU us/step':>12s}")
    for r in result["rows"]:
        k = "" if r["envs_per_process"] is None else str(r["envs_per_process"])
        case = f"{r['side']}x{r['side']} N={r['num_envs']}"
        lines.append(f"{case:14s} {r['name']:24s} {k:>3s} {r['steps_per_s']:9.0f} {r['cpu_us_per_step']:12.0f}")
    lines.append("")
    lines.append(f"{'case':14s} {'ratio':36s} {'value':>6s} {'target':>9s}")
    for r in result["ratios"]:
        target = "" if r["target"] is None else f">={r['target']:.1f} {'ok' if r['value'] >= r['target'] else 'MISS'}"
        lines.append(f"{r['case']:14s} {r['ratio']:36s} {r['value']:6.2f} {target:>9s}")
    m = result["machine"]
    lines.append("")
    lines.append(
        f"machine: {m['cpus']} CPUs, {m['platform']}; load average at end {m['load_avg_at_end'][0]:.2f}; "
        f"{result['rounds']} rounds x {result['duration_s']:g} s per contender; CPU hogs: {result['hogs']}; "
        f"scene renders in its hook: {'yes' if result.get('render_in_hook') else 'no'}; "
        f"LP_NUM_THREADS in this process: {m['LP_NUM_THREADS'] or 'unset'}"
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    cases = parse_cases(args.pixels_cases)
    try:
        ks = [int(k) for k in args.pixels_k.split(",") if k.strip()] if args.pixels_k else []
    except ValueError:
        raise SystemExit(f"--pixels-k must be comma-separated ints >= 1, got {args.pixels_k[:40]!r}") from None
    if args.hog < 0 or any(k < 1 for k in ks):
        raise SystemExit("--hog must be >= 0 and --pixels-k >= 1")
    check_memory(cases, world_footprint)
    log = progress_log(args.json)
    result = measure(
        cases, args.pixels_duration, args.pixels_rounds, args.hog, ks, log=log, in_hook=args.pixels_render_in_hook
    )
    emit(result, args.json, format_table)
    return 0


__all__ = ["check_memory", "max_side", "measure", "parse_cases", "ratios", "world_footprint"]
