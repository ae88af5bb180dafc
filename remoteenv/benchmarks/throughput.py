"""``python -m remoteenv bench``: steps/s of remoteenv next to in-process Gymnasium.

Agent side; it launches sims. Everything is measured in one run on one
machine, one contender at a time, each for ``--duration`` seconds after a
short warm-up, with pre-drawn random actions, resetting (or autoresetting)
whenever an episode ends. Figures are env steps per second (a vector step of
N worlds counts N). Ratios, not absolute numbers, are what carry over to
another machine. It measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from remoteenv import SHIPPED_SCENES
from remoteenv.benchmarks.harness.report import emit, machine_record, progress_log
from remoteenv.benchmarks.harness.timing import timed as _timed
from remoteenv.benchmarks.harness.transport_floor import pipe_floor, zmq_floor

#: remoteenv scene -> (remoteenv id, Gymnasium id to compare with)
SCENES = {
    "reacher": (SHIPPED_SCENES["reacher"], "Reacher-v5"),
    "cartpole": (SHIPPED_SCENES["cartpole"], "CartPole-v1"),
}
DEFAULT_NUM_ENVS = (1, 2, 4, 8, 16)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("throughput benchmark (default mode)")
    g.add_argument(
        "--scenes",
        default="reacher,cartpole",
        help=f"comma-separated scenes to measure, from {sorted(SCENES)} (default: both)",
    )
    g.add_argument(
        "--num-envs",
        default=",".join(map(str, DEFAULT_NUM_ENVS)),
        help="comma-separated vector sizes N (default 1,2,4,8,16)",
    )
    g.add_argument(
        "--duration",
        type=float,
        default=1.0,
        help="seconds each contender is timed (default 1.0; the default run takes ~3 min)",
    )
    g.add_argument(
        "--envs-per-process",
        type=int,
        default=None,
        help="K of the batched RemoteVectorEnv rows (default: RemoteVectorEnv's own, max(8, ceil(N / cpus)) capped at N)",
    )
    g.add_argument(
        "--json",
        default=None,
        metavar="PATH",
        help="also write the results as JSON to PATH ('-' for stdout, replacing the table)",
    )


# ---------------------------------------------------------------- timing


def _single_rate(env: gym.Env, duration: float, seed: int = 0) -> float:
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(256)]
    env.reset(seed=seed)

    def step(i: int) -> None:
        _, _, terminated, truncated, _ = env.step(actions[i & 255])
        if terminated or truncated:
            env.reset()

    return _timed(step, duration)


def _vector_rate(env: Any, duration: float, seed: int = 0) -> float:
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(64)]
    env.reset(seed=seed)

    def step(i: int) -> None:
        env.step(actions[i & 63])

    return _timed(step, duration, warmup=20) * env.num_envs


def _measure(make: Callable[[], Any], rate: Callable[[Any, float], float], duration: float) -> float | None:
    try:
        env = make()
    except Exception as exc:  # e.g. a Gymnasium env whose extra is not installed
        print(f"  (skipped: {type(exc).__name__}: {exc})", file=sys.stderr)
        return None
    try:
        return rate(env, duration)
    finally:
        env.close()


# ---------------------------------------------------------------- run


def _parse_ints(text: str, what: str) -> list[int]:
    try:
        values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise SystemExit(f"{what} must be comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise SystemExit(f"{what} must be positive integers, got {text!r}")
    return values


def measure(
    scenes: list[str],
    num_envs: list[int],
    duration: float,
    envs_per_process: int | None = None,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Run every contender; returns ``{"machine", "floor", "rows", "ratios"}``."""
    import remoteenv  # noqa: F401  (registers the ids)
    from remoteenv.vector_env import default_envs_per_process

    rows: list[dict[str, Any]] = []

    def record(scene: str, name: str, n: int, rate: float | None, k: int | None = None) -> None:
        rows.append({"scene": scene, "name": name, "num_envs": n, "envs_per_process": k, "steps_per_s": rate})
        shown = "skipped" if rate is None else f"{rate:10.0f} steps/s"
        log(f"  {scene:9s} {name:28s} N={n:<3d}{'' if k is None else f' K={k:<3d}'} {shown}")

    log(f"measuring, {duration:g} s per contender ...")
    floor = zmq_floor(duration)
    log(f"  raw pyzmq+msgpack round trip: {1e6 / floor:.0f} us ({floor:.0f}/s)")
    pfloor = pipe_floor(duration)
    log(f"  raw socketpair+msgpack round trip: {1e6 / pfloor:.0f} us ({pfloor:.0f}/s)")
    for scene in scenes:
        remote_id, gym_id = SCENES[scene]
        record(scene, "gymnasium in-process", 1, _measure(lambda: gym.make(gym_id), _single_rate, duration))
        record(scene, "remoteenv single", 1, _measure(lambda: gym.make(remote_id), _single_rate, duration))
        record(
            scene,
            "remoteenv single, zmq ipc",
            1,
            _measure(lambda: gym.make(remote_id, transport="ipc"), _single_rate, duration),
        )
        for n in num_envs:
            record(
                scene,
                "gymnasium SyncVectorEnv",
                n,
                _measure(lambda: gym.make_vec(gym_id, num_envs=n, vectorization_mode="sync"), _vector_rate, duration),
            )
            record(
                scene,
                "gymnasium AsyncVectorEnv",
                n,
                _measure(lambda: gym.make_vec(gym_id, num_envs=n, vectorization_mode="async"), _vector_rate, duration),
            )
            record(
                scene,
                "RemoteVectorEnv K=1",
                n,
                _measure(
                    lambda: gym.make_vec(
                        remote_id, num_envs=n, vectorization_mode="vector_entry_point", envs_per_process=1
                    ),
                    _vector_rate,
                    duration,
                ),
                1,
            )
            # Without --envs-per-process the env's default layout (for these cheap scenes stepped as
            # one batch, the K shown, its physics threads with it).
            k = min(envs_per_process or default_envs_per_process(n), n)
            layout: dict[str, Any] = {"envs_per_process": k} if envs_per_process else {}
            if k > 1:
                record(
                    scene,
                    "RemoteVectorEnv batched",
                    n,
                    _measure(
                        lambda: gym.make_vec(remote_id, num_envs=n, vectorization_mode="vector_entry_point", **layout),
                        _vector_rate,
                        duration,
                    ),
                    k,
                )
    return {
        "machine": {**machine_record(), "load_avg_at_end": list(os.getloadavg())},
        "duration_s": duration,
        "floor_round_trips_per_s": floor,
        "pipe_floor_round_trips_per_s": pfloor,
        "rows": rows,
        "ratios": ratios(rows),
    }


def ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The side-by-side ratios the project targets."""

    def rate(scene: str, name: str, n: int) -> float | None:
        for r in rows:
            if r["scene"] == scene and r["name"] == name and r["num_envs"] == n:
                return r["steps_per_s"]
        return None

    out = []

    def add(scene: str, what: str, num: float | None, den: float | None, target: float | None) -> None:
        if num and den:
            out.append({"scene": scene, "ratio": what, "value": num / den, "target": target})

    for scene in sorted({r["scene"] for r in rows}):
        add(
            scene,
            "remoteenv single / AsyncVectorEnv(1)",
            rate(scene, "remoteenv single", 1),
            rate(scene, "gymnasium AsyncVectorEnv", 1),
            2.0,
        )
        add(
            scene,
            "remoteenv single / in-process",
            rate(scene, "remoteenv single", 1),
            rate(scene, "gymnasium in-process", 1),
            None,
        )
        add(
            scene,
            "remoteenv single / the same over zmq ipc",
            rate(scene, "remoteenv single", 1),
            rate(scene, "remoteenv single, zmq ipc", 1),
            None,
        )
        for n in sorted({r["num_envs"] for r in rows if r["scene"] == scene}):
            add(
                scene,
                f"RemoteVectorEnv K=1 / AsyncVectorEnv, N={n}",
                rate(scene, "RemoteVectorEnv K=1", n),
                rate(scene, "gymnasium AsyncVectorEnv", n),
                1.3,
            )
            add(
                scene,
                f"RemoteVectorEnv batched / AsyncVectorEnv, N={n}",
                rate(scene, "RemoteVectorEnv batched", n),
                rate(scene, "gymnasium AsyncVectorEnv", n),
                None,
            )
            add(
                scene,
                f"RemoteVectorEnv batched / SyncVectorEnv, N={n}",
                rate(scene, "RemoteVectorEnv batched", n),
                rate(scene, "gymnasium SyncVectorEnv", n),
                1.0 if n == 16 else None,
            )
    return out


def format_table(result: dict[str, Any]) -> str:
    lines = [
        f"raw pyzmq + msgpack round trip (ipc): {1e6 / result['floor_round_trips_per_s']:.0f} us "
        f"= {result['floor_round_trips_per_s']:.0f} round trips/s",
        f"raw socketpair + msgpack round trip (blocking reads): "
        f"{1e6 / result['pipe_floor_round_trips_per_s']:.0f} us "
        f"= {result['pipe_floor_round_trips_per_s']:.0f} round trips/s",
        "",
    ]
    lines.append(f"{'scene':9s} {'contender':26s} {'N':>3s} {'K':>3s} {'steps/s':>10s}")
    for r in result["rows"]:
        k = "" if r["envs_per_process"] is None else str(r["envs_per_process"])
        v = "skipped" if r["steps_per_s"] is None else f"{r['steps_per_s']:.0f}"
        lines.append(f"{r['scene']:9s} {r['name']:26s} {r['num_envs']:>3d} {k:>3s} {v:>10s}")
    lines.append("")
    lines.append(f"{'scene':9s} {'ratio':52s} {'value':>6s} {'target':>7s}")
    for r in result["ratios"]:
        target = "" if r["target"] is None else (f">={r['target']:.1f} {'ok' if r['value'] >= r['target'] else 'MISS'}")
        lines.append(f"{r['scene']:9s} {r['ratio']:52s} {r['value']:6.2f} {target:>7s}")
    m = result["machine"]
    lines.append("")
    lines.append(
        f"machine: {m['cpus']} CPUs, {m['platform']}, Python {m['python']}; "
        f"load average at end {m['load_avg_at_end'][0]:.2f}; {result['duration_s']:g} s per contender"
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    unknown = [s for s in scenes if s not in SCENES]
    if unknown or not scenes:
        raise SystemExit(f"unknown scenes {unknown}; choose from {sorted(SCENES)}")
    num_envs = _parse_ints(args.num_envs, "--num-envs")
    if args.duration <= 0:
        raise SystemExit(f"--duration must be > 0 seconds, got {args.duration}")
    result = measure(scenes, num_envs, args.duration, args.envs_per_process, log=progress_log(args.json))
    emit(result, args.json, format_table)
    return 0
