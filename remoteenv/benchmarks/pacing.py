"""``python -m remoteenv bench --real-time``: how closely real-time mode keeps time.

Runs continuous CartPole under ``real_time=True`` for ``--rt-duration``
seconds of wall time, balanced by the LQR controller with a random think time
per step (so actions arrive at every phase of a substep; a fallen pole is
reset and the run goes on). Then asks the sim process for its timing figures
and prints:

- pacing error: wall seconds between each substep's deadline
  (``t0 + n * timestep / factor``) and the moment the sim processed it;
  p50/p99/max and the overruns (substeps more than one substep late).
- arrival to application: wall seconds between a step request's arrival in
  the sim process and the substep where its action took effect (the goal is
  at most one physics substep).
- the agent's view: action latency in sim time, wall round trip, late actions.
- sim seconds advanced per wall second, measured over the same run.

With ``--rt-hog N`` it runs ``N`` CPU-bound processes beside the benchmark
(plain busy loops, started before and stopped after), to see pacing on a busy
host. With ``--rt-levers`` it runs the benchmark once per configuration of
the sim's pacing levers (:mod:`remoteenv.sim.process.pacing_levers`: the spin window,
the garbage collector, CPU affinity, ``SCHED_FIFO``; each alone, then all)
and prints one comparison table, each row next to the baseline. It notes
the load average before each run.

It measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import time
from typing import Any

import numpy as np

from remoteenv.agent.connection.connect import Connection
from remoteenv.agent.launch.launcher import Launcher
from remoteenv.agent.session.latency_stats import LatencyStats
from remoteenv.scene_controllers.cartpole import cartpole_continuous
from remoteenv.wire import protocol


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("real-time benchmark (--real-time)")
    g.add_argument("--rt-duration", type=float, default=30.0, help="wall seconds to run (default 30)")
    g.add_argument(
        "--rt-factor", type=float, default=1.0, help="real_time_factor: simulated seconds per wall second (default 1.0)"
    )
    g.add_argument(
        "--rt-max-think-ms",
        type=float,
        default=10.0,
        help="the agent sleeps U(0, this) ms before each action (default 10)",
    )
    g.add_argument("--rt-seed", type=int, default=0, help="seed of resets and think times (default 0)")
    g.add_argument("--rt-hog", type=int, default=0, help="run this many CPU-bound processes beside the benchmark")
    g.add_argument(
        "--rt-levers", action="store_true", help="compare the pacing levers: one run per configuration (see --help)"
    )
    g.add_argument(
        "--rt-sim-args", default="", help="extra scene arguments for the sim, e.g. '--rt-gc freeze --rt-priority 50'"
    )


def _ms(s: dict[str, Any]) -> str:
    return f"n={s['count']:6d}  p50 {1e3 * s['p50']:7.3f}  p99 {1e3 * s['p99']:7.3f}  max {1e3 * s['max']:8.3f} ms"


#: The lever configurations ``--rt-levers`` compares: name -> scene arguments.
#: Affinity pins the sim to the last CPU and the agent (this process) to the others.
LEVERS: dict[str, list[str]] = {
    "baseline": [],
    "spin 1 ms": ["--rt-spin-s", "0.001"],
    "gc freeze": ["--rt-gc", "freeze"],
    "affinity": ["--rt-cpus", str((os.cpu_count() or 1) - 1)],
    "SCHED_FIFO 50": ["--rt-priority", "50"],
    "all": [
        "--rt-spin-s",
        "0.001",
        "--rt-gc",
        "freeze",
        "--rt-cpus",
        str((os.cpu_count() or 1) - 1),
        "--rt-priority",
        "50",
    ],
}


def start_hogs(n: int) -> list[subprocess.Popen[bytes]]:
    """``n`` processes that spin on the CPU until stopped."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def stop_hogs(hogs: list[subprocess.Popen[bytes]]) -> None:
    for hog in hogs:
        hog.kill()
    for hog in hogs:
        hog.wait()


def run(args: argparse.Namespace) -> int:
    hogs = start_hogs(args.rt_hog)
    try:
        if not args.rt_levers:
            result = measure(args, shlex.split(args.rt_sim_args), verbose=True)
            print_result(result)
            return 0
        if os.geteuid() == 0:
            print("running as root: SCHED_FIFO is allowed")
        else:
            print("not root: SCHED_FIFO is refused unless this user has CAP_SYS_NICE or an RLIMIT_RTPRIO")
        rows = []
        for name, sim_args in LEVERS.items():
            agent_cpus = None
            if "--rt-cpus" in sim_args and (os.cpu_count() or 1) > 1:
                agent_cpus = os.sched_getaffinity(0)
                os.sched_setaffinity(0, set(range((os.cpu_count() or 1) - 1)))
            try:
                rows.append((name, measure(args, [*sim_args, *shlex.split(args.rt_sim_args)], verbose=False)))
            finally:
                if agent_cpus is not None:
                    os.sched_setaffinity(0, agent_cpus)
            print(f"  {name}: done (load {rows[-1][1]['load']:.2f})", flush=True)
        print_levers(rows, args.rt_hog)
        return 0
    finally:
        stop_hogs(hogs)


def print_levers(rows: list[tuple[str, dict[str, Any]]], hogs: int) -> None:
    print(f"\npacing levers, {hogs} CPU hog(s) beside; milliseconds of wall time")
    print(
        f"{'configuration':14s} {'load':>5s} {'pace p50':>9s} {'pace p99':>9s} {'pace max':>9s} "
        f"{'overruns':>8s} {'apply p99':>9s} {'apply max':>9s} {'rt p99':>8s}"
    )
    for name, r in rows:
        pacing, apply, rt = r["timing"]["pacing_error_s"], r["timing"]["apply_delay_s"], r["round_trip"]
        print(
            f"{name:14s} {r['load']:5.2f} {1e3 * pacing['p50']:9.3f} {1e3 * pacing['p99']:9.3f} "
            f"{1e3 * pacing['max']:9.3f} {r['timing']['overruns']:8d} {1e3 * apply['p99']:9.3f} "
            f"{1e3 * apply['max']:9.3f} {1e3 * rt['p99']:8.3f}"
        )


def measure(args: argparse.Namespace, sim_args: list[str], verbose: bool) -> dict[str, Any]:
    """One benchmark run with ``sim_args`` for the sim; its figures."""
    import remoteenv

    duration, factor = float(args.rt_duration), float(args.rt_factor)
    max_think = float(args.rt_max_think_ms) / 1e3
    rng = np.random.default_rng(args.rt_seed)
    launcher = Launcher(
        remoteenv.scene_path("cartpole"),
        1,
        seed=args.rt_seed,
        env_kwargs={"continuous": True},
        real_time=True,
        real_time_factor=factor,
        extra_args=sim_args,
    )
    load = os.getloadavg()[0]
    conn: Connection | None = None
    try:
        conn = Connection(launcher.endpoints[0], death_check=launcher.sims[0].death)
        hs = conn.request("handshake", protocol=protocol.PROTOCOL_VERSION)
        timestep = float(hs["metadata"]["timestep"])
        period = timestep / factor
        if verbose:
            print(
                f"real-time benchmark: continuous CartPole, factor {factor:g}, {duration:g} s of wall "
                f"time, substep {1e3 * timestep:.3f} ms sim = {1e3 * period:.3f} ms wall, "
                f"think U(0, {1e3 * max_think:g}) ms, {args.rt_hog} CPU hog(s), load average {load:.2f}"
                + (f", sim arguments {' '.join(sim_args)}" if sim_args else "")
            )
        stats = LatencyStats()
        sim_seconds = 0.0
        episodes = 0
        start = time.monotonic()
        obs = conn.request("reset", seed=args.rt_seed)["obs"]
        conn.request("timing", clear=True)
        while time.monotonic() - start < duration:
            time.sleep(rng.uniform(0.0, max_think))
            sent = time.perf_counter()
            reply = conn.request("step", action=cartpole_continuous(obs))
            stats.record(reply["info"], time.perf_counter() - sent)
            obs = reply["obs"]
            if reply["terminated"]:
                sim_seconds += reply["info"]["sim_time"]
                episodes += 1
                obs = conn.request("reset")["obs"]
        wall = time.monotonic() - start
        timing = conn.request("timing")["worlds"][0]
        if not reply["terminated"]:
            sim_seconds += reply["info"]["sim_time"]
    finally:
        if conn is not None:
            conn.close()
        launcher.close()

    return {
        "timing": timing,
        "stats": stats,
        "round_trip": stats.round_trip_s.summary(),
        "period": period,
        "episodes": episodes,
        "sim_per_wall": sim_seconds / wall,
        "load": load,
    }


def print_result(r: dict[str, Any]) -> None:
    timing, stats, period, episodes = r["timing"], r["stats"], r["period"], r["episodes"]
    pacing, apply = timing["pacing_error_s"], timing["apply_delay_s"]
    lat = stats.latency_s.summary()
    rt = stats.round_trip_s.summary()
    print(
        f"pacing error           {_ms(pacing)}   overruns {timing['overruns']} (substeps > {1e3 * period:.3f} ms late)"
    )
    print(f"arrival -> application {_ms(apply)}   goal <= one substep ({1e3 * period:.3f} ms)")
    print(
        f"action latency (sim)   n={lat['count']:6d}  mean {1e3 * lat['mean']:7.3f}  "
        f"p50 {1e3 * lat['p50']:7.3f}  p99 {1e3 * lat['p99']:7.3f}  max {1e3 * lat['max']:8.3f} ms"
    )
    print(f"wall round trip        {_ms(rt)}")
    print(
        f"steps {stats.steps}, late actions {stats.late_actions}, episodes ended {episodes}, "
        f"sim seconds per wall second {r['sim_per_wall']:.4f} (includes reset gaps)"
    )
