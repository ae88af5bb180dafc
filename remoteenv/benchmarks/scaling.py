"""Agent-side cost of driving sim processes over TCP + CURVE, for docs/scaling.md.

Agent side; it launches sims on this machine, connected as a cluster's sims
are (TCP, CURVE on; Ray carries no env traffic, so placing the sims on
other nodes changes the network, not the agent's work). For each number of
sim processes P and worlds per process K it steps a lock-step
``RemoteVectorEnv`` of Reacher with random actions and reports:

- the agent process's CPU time per vector step (``time.process_time``: its
  own thread and ZeroMQ's I/O threads): the fan-out (encode and send P
  requests) and fan-in (poll, receive, decode, assemble) that the agent pays
  whatever machine the sims run on;
- bytes on the loopback interface per vector step (TCP/IP, CURVE and
  msgpack together), when run in a private network namespace where nothing
  else uses loopback (``unshare -n``; otherwise the column is left out);
- the wall step rate, which on a small machine is bounded by the sims'
  physics sharing the agent's cores, not by the agent.

A least-squares line ``cpu = a + b * P`` per K gives the per-process cost
``b``; one agent core at a vector step rate R can drive about
``(1 / R - a) / b`` processes. It measures and prints; it asserts nothing.

    unshare -n bash -c 'ip link set lo up && exec python -m remoteenv.benchmarks.scaling'
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import numpy as np

DEFAULT_PROCESSES = (1, 2, 4, 8, 16, 32)
DEFAULT_WORLDS = (1, 8)
#: Vector step rates (Hz) the projection is printed for.
RATES_HZ = (10, 50, 200)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("scaling benchmark")
    g.add_argument(
        "--processes",
        default=",".join(map(str, DEFAULT_PROCESSES)),
        help="comma-separated numbers of sim processes P (default 1,2,4,8,16,32)",
    )
    g.add_argument(
        "--worlds",
        default=",".join(map(str, DEFAULT_WORLDS)),
        help="comma-separated worlds per process K (default 1,8)",
    )
    g.add_argument("--steps", type=int, default=400, help="timed vector steps per row (default 400)")
    g.add_argument("--json", default=None, metavar="PATH", help="also write the rows as JSON to PATH")


def _loopback_bytes() -> int | None:
    """Bytes received on ``lo`` so far (each loopback byte is received once), or None."""
    try:
        with open("/proc/net/dev") as f:
            for line in f:
                name, _, rest = line.partition(":")
                if name.strip() == "lo":
                    return int(rest.split()[0])
    except OSError:
        pass
    return None


def _private_loopback() -> bool:
    """True in a network namespace whose only interface is loopback."""
    try:
        with open("/proc/net/dev") as f:
            names = [line.partition(":")[0].strip() for line in f.readlines()[2:]]
    except OSError:
        return False
    return names == ["lo"]


def measure(processes: int, worlds: int, steps: int) -> dict[str, Any]:
    """One row: agent CPU and loopback bytes per vector step of P processes of K worlds."""
    import gymnasium as gym

    from remoteenv import SHIPPED_SCENES
    from remoteenv.vector_env import RemoteVectorEnv

    spec = gym.spec(SHIPPED_SCENES["reacher"])
    envs = RemoteVectorEnv(
        spec.kwargs["scene"],
        processes * worlds,
        envs_per_process=worlds,
        transport="tcp",
        curve=True,
        max_episode_steps=spec.max_episode_steps,
    )
    try:
        rng = np.random.default_rng(0)
        actions = rng.uniform(-1, 1, size=(64, *(envs.action_space.shape or ()))).astype(np.float32)
        envs.reset(seed=0)
        for i in range(50):
            envs.step(actions[i % 64])
        net0, cpu0, wall0 = _loopback_bytes(), time.process_time(), time.perf_counter()
        for i in range(steps):
            envs.step(actions[i % 64])
        wall, cpu, net = time.perf_counter() - wall0, time.process_time() - cpu0, _loopback_bytes()
    finally:
        envs.close()
    row: dict[str, Any] = {
        "processes": processes,
        "worlds_per_process": worlds,
        "steps": steps,
        "agent_cpu_us_per_step": 1e6 * cpu / steps,
        "agent_cpu_us_per_process_step": 1e6 * cpu / steps / processes,
        "vector_steps_per_s": steps / wall,
    }
    if net is not None and net0 is not None and _private_loopback():
        row["bytes_per_step"] = (net - net0) / steps
    return row


def measure_render(steps: int) -> dict[str, Any] | None:
    """Bytes on loopback per ``render()`` of one Reacher world (rgb_array), or None
    outside a private network namespace."""
    if not _private_loopback():
        return None
    import gymnasium as gym

    from remoteenv import SHIPPED_SCENES
    from remoteenv.remote_env import OpenAIRemoteEnv

    spec = gym.spec(SHIPPED_SCENES["reacher"])
    env = OpenAIRemoteEnv(spec.kwargs["scene"], render_mode="rgb_array", transport="tcp", curve=True)
    try:
        env.reset(seed=0)
        frame = env.render()
        net0 = _loopback_bytes()
        for _ in range(steps):
            env.render()
        net = _loopback_bytes()
    finally:
        env.close()
    assert frame is not None and net is not None and net0 is not None
    return {
        "frame_shape": list(frame.shape),
        "frame_bytes": int(frame.nbytes),
        "bytes_per_render": (net - net0) / steps,
    }


def fit(rows: list[dict[str, Any]]) -> dict[int, tuple[float, float]]:
    """Per K: ``(a, b)`` of the least-squares line ``cpu_us = a + b * P``."""
    lines = {}
    for k in sorted({r["worlds_per_process"] for r in rows}):
        sel = [r for r in rows if r["worlds_per_process"] == k]
        if len(sel) < 2:
            continue
        p = np.array([r["processes"] for r in sel], dtype=float)
        c = np.array([r["agent_cpu_us_per_step"] for r in sel])
        b, a = np.polyfit(p, c, 1)
        lines[k] = (float(a), float(b))
    return lines


def run(args: argparse.Namespace) -> int:
    processes = [int(x) for x in args.processes.split(",")]
    worlds = [int(x) for x in args.worlds.split(",")]
    print(
        f"# load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs; "
        f"private loopback: {_private_loopback()}"
    )
    print(f"{'P':>4} {'K':>3} {'agent CPU us/step':>18} {'us/process':>11} {'steps/s':>8} {'bytes/step':>11}")
    rows = []
    for k in worlds:
        for p in processes:
            row = measure(p, k, args.steps)
            rows.append(row)
            net = row.get("bytes_per_step")
            print(
                f"{p:4d} {k:3d} {row['agent_cpu_us_per_step']:18.0f} {row['agent_cpu_us_per_process_step']:11.1f} "
                f"{row['vector_steps_per_s']:8.0f} {'-' if net is None else f'{net:11.0f}'}",
                flush=True,
            )
    render = measure_render(max(10, args.steps // 10))
    if render is not None:
        print(
            f"render: one {'x'.join(map(str, render['frame_shape']))} frame ({render['frame_bytes']} bytes) "
            f"costs {render['bytes_per_render']:.0f} bytes on the wire"
        )
    print(f"# load average after: {os.getloadavg()[0]:.2f}")
    for k, (a, b) in fit(rows).items():
        reach = ", ".join(f"{rate} Hz: {max(0, int((1e6 / rate - a) / b))}" for rate in RATES_HZ)
        print(
            f"K={k}: agent CPU per vector step = {a:.0f} us + {b:.1f} us per process; "
            f"processes one agent core drives at {reach}"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": rows, "fit": {str(k): v for k, v in fit(rows).items()}, "render": render}, f, indent=2)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
