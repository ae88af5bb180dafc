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

It measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from remoteenv import controllers
from remoteenv.agent.connection import Connection
from remoteenv.agent.latency import LatencyStats
from remoteenv.agent.launcher import Launcher
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


def _ms(s: dict[str, Any]) -> str:
    return f"n={s['count']:6d}  p50 {1e3 * s['p50']:7.3f}  p99 {1e3 * s['p99']:7.3f}  max {1e3 * s['max']:8.3f} ms"


def run(args: argparse.Namespace) -> int:
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
    )
    conn: Connection | None = None
    try:
        conn = Connection(launcher.endpoints[0], death_check=launcher.sims[0].death)
        hs = conn.request("handshake", protocol=protocol.PROTOCOL_VERSION)
        timestep = float(hs["metadata"]["timestep"])
        period = timestep / factor
        print(
            f"real-time benchmark: continuous CartPole, factor {factor:g}, {duration:g} s of wall "
            f"time, substep {1e3 * timestep:.3f} ms sim = {1e3 * period:.3f} ms wall, "
            f"think U(0, {1e3 * max_think:g}) ms"
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
            reply = conn.request("step", action=controllers.cartpole_continuous(obs))
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
        f"sim seconds per wall second {sim_seconds / wall:.4f} (includes reset gaps)"
    )
    return 0
