"""``python -m remoteenv bench --batched``: batched stepping next to its anchors.

Agent side; it launches sims. Reacher at N = 16 and 64 (``--batched-n``), and
the hexapod (the heavy, contact-rich scene) next to its own physics limit:
the physics limit (raw ``mj_step``, one thread per CPU,
:class:`~remoteenv.benchmarks.harness.anchors.PhysicsLimit`; and on one thread), EnvPool's
``Reacher-v5`` (skipped with a note when EnvPool is not installed),
remoteenv's batched ``RemoteVectorEnv`` (default K) stepped with ``step``
and with ``send``/``recv`` (``batch_size`` = N / 2), Gymnasium's
``SyncVectorEnv``; and at N = 1 a single remote env next to
``AsyncVectorEnv(1)``. Every contender is built first, then all are timed
in ``--rounds`` alternating rounds of ``--batched-duration`` seconds each, so
load that comes and goes hits them alike; the table shows each contender's
median and the ratios the project targets (issue 13). ``--hog`` runs CPU
hogs beside the measurement; ``--profile`` instead times each stage of one
batched step in this process. It measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from remoteenv.benchmarks.harness.anchors import CpuHog, PhysicsLimit, cpu_seconds, make_envpool
from remoteenv.benchmarks.harness.report import emit, progress_log, rounds_record

REMOTE_ID = "remoteenv/Reacher-v0"
GYM_ID = "Reacher-v5"
#: The heavy, contact-rich case: 18 servos, six feet on a floor (no in-process twin to compare).
HEAVY_ID = "remoteenv/Hexapod-v0"
#: (ratio name, numerator contender, denominator contender, N, target)
TARGETS = [
    ("batched / EnvPool", "remoteenv batched", "EnvPool", 64, 1.0),
    ("batched / physics limit", "remoteenv batched", "physics limit", 64, 0.6),
    ("batched / SyncVectorEnv", "remoteenv batched", "SyncVectorEnv", 16, 2.0),
    ("single remote / AsyncVectorEnv(1)", "remoteenv single", "AsyncVectorEnv", 1, 2.0),
    ("send-recv / EnvPool", "remoteenv send/recv", "EnvPool", 64, None),
    ("batched / EnvPool", "remoteenv batched", "EnvPool", 16, None),
    ("EnvPool / physics limit", "EnvPool", "physics limit", 64, None),
    ("physics limit / physics, 1 thread", "physics limit", "physics, 1 thread", 64, None),
    ("hexapod batched / hexapod physics limit", "hexapod batched", "hexapod physics limit", 16, None),
    ("hexapod batched / hexapod physics limit", "hexapod batched", "hexapod physics limit", 64, None),
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("batched benchmark (--batched)")
    g.add_argument("--batched-n", default="16,64", help="comma-separated vector sizes N (default 16,64)")
    g.add_argument("--batched-duration", type=float, default=1.0, help="seconds per contender per round (default 1)")
    g.add_argument("--rounds", type=int, default=5, help="alternating rounds; medians are shown (default 5)")
    g.add_argument(
        "--profile",
        action="store_true",
        help="instead: time each stage of one batched step in this process (no sims; see step_profile)",
    )
    g.add_argument("--no-heavy", action="store_true", help="skip the hexapod rows (the heavy, contact-rich scene)")
    g.add_argument(
        "--hog", type=int, nargs="?", const=1, default=0, help="run this many CPU hogs beside it (default 1 if given)"
    )


# ---------------------------------------------------------------- contenders


class Contender:
    """A named thing to time: ``tick()`` advances ``per_tick`` env steps."""

    def __init__(self, name: str, n: int, env: Any, tick: Callable[[int], None], per_tick: int) -> None:
        self.name, self.n, self.env, self.tick, self.per_tick = name, n, env, tick, per_tick
        self.rates: list[float] = []
        self.cpu_us: list[float] = []

    def measure(self, duration: float, exclude: frozenset[int] = frozenset()) -> None:
        """Time ``tick`` for ``duration`` s; record steps/s and CPU microseconds per step
        (this process and its children but ``exclude``)."""
        calls = 0
        cpu = cpu_seconds(exclude)
        start = time.perf_counter()
        end = start + duration
        now = start
        while now < end:
            for _ in range(10):
                self.tick(calls)
                calls += 1
            now = time.perf_counter()
        steps = calls * self.per_tick
        self.rates.append(steps / (now - start))
        self.cpu_us.append((cpu_seconds(exclude) - cpu) / steps * 1e6)

    def close(self) -> None:
        close = getattr(self.env, "close", None)
        if close is not None:
            close()


def _box_actions(n: int, count: int = 64, dim: int = 2) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [rng.uniform(-1, 1, size=(n, dim)).astype(np.float32) for _ in range(count)]


def _vector(name: str, n: int, env: Any, seeded: bool = False, dim: int = 2) -> Contender:
    """``env.step`` over N worlds with ``dim`` action entries each; ``seeded``: the env
    took its seed when made (EnvPool)."""
    actions = _box_actions(n, dim=dim)
    env.reset() if seeded else env.reset(seed=0)
    return Contender(name, n, env, lambda i: env.step(actions[i & 63]), n)


def _send_recv(n: int) -> Contender:
    env: Any = gym.make_vec(REMOTE_ID, num_envs=n, vectorization_mode="vector_entry_point", batch_size=n // 2)
    actions = _box_actions(n // 2)
    env.reset(seed=0)
    env.send(np.zeros((n, 2), dtype=np.float32))

    def tick(i: int) -> None:
        info = env.recv()[4]
        env.send(actions[i & 63], info["env_id"])

    return Contender("remoteenv send/recv", n, env, tick, n // 2)


def _single(name: str, env: Any) -> Contender:
    actions = _box_actions(1)
    env.reset(seed=0)
    vector = hasattr(env, "num_envs")

    def tick(i: int) -> None:
        a = actions[i & 63]
        if vector:
            env.step(a)
        else:
            _, _, terminated, truncated, _ = env.step(a[0])
            if terminated or truncated:
                env.reset()

    return Contender(name, 1, env, tick, 1)


def _physics_tick(physics: PhysicsLimit) -> Callable[[int], None]:
    return lambda i: physics.step()


def build(ns: list[int], log: Callable[[str], None], heavy: bool = True) -> list[Contender]:
    """Every contender, ready to time (EnvPool skipped with a note if it is missing;
    ``heavy``: also the hexapod's physics limit and batched remote env)."""
    import remoteenv

    model = os.path.join(os.path.dirname(remoteenv.scene_path("reacher")), "reacher.xml")
    out: list[Contender] = []
    for n in ns:
        physics = PhysicsLimit(model, n, frame_skip=2)
        out.append(Contender("physics limit", n, physics, _physics_tick(physics), n))
        serial = PhysicsLimit(model, n, frame_skip=2, threads=1)
        out.append(Contender("physics, 1 thread", n, serial, _physics_tick(serial), n))
        try:
            out.append(_vector("EnvPool", n, make_envpool(GYM_ID, n), seeded=True))
        except ImportError:
            log("  EnvPool is not installed (pip install 'remoteenv[bench]'): its rows are skipped")
        out.append(_vector("remoteenv batched", n, gym.make_vec(REMOTE_ID, n, vectorization_mode="vector_entry_point")))
        if n >= 2:
            out.append(_send_recv(n))
        out.append(_vector("SyncVectorEnv", n, gym.make_vec(GYM_ID, n, vectorization_mode="sync")))
    if heavy:
        hexapod = os.path.join(os.path.dirname(remoteenv.scene_path("hexapod")), "hexapod.xml")
        for n in ns:
            physics = PhysicsLimit(hexapod, n, frame_skip=4)
            out.append(Contender("hexapod physics limit", n, physics, _physics_tick(physics), n))
            env = gym.make_vec(HEAVY_ID, n, vectorization_mode="vector_entry_point")
            out.append(_vector("hexapod batched", n, env, dim=18))
    out.append(_single("remoteenv single", gym.make(REMOTE_ID)))
    out.append(_vector("AsyncVectorEnv", 1, gym.make_vec(GYM_ID, 1, vectorization_mode="async")))
    return out


# ---------------------------------------------------------------- run


def measure(
    ns: list[int], duration: float, rounds: int, hog: int, log: Callable[[str], None] = print, heavy: bool = True
) -> dict[str, Any]:
    contenders = build(ns, log, heavy)
    loads = []
    try:
        with CpuHog(hog) as hogs:
            for c in contenders:  # warm up
                c.measure(min(0.2, duration), hogs.pids)
                c.rates.clear()
                c.cpu_us.clear()
            for r in range(rounds):
                for c in contenders:
                    c.measure(duration, hogs.pids)
                loads.append(os.getloadavg()[0])
                log(f"  round {r + 1}/{rounds} done, load average {loads[-1]:.2f}")
    finally:
        for c in contenders:
            c.close()
    rows = [
        {
            "name": c.name,
            "num_envs": c.n,
            "median": statistics.median(c.rates),
            "rates": c.rates,
            "cpu_us_per_step": statistics.median(c.cpu_us),
        }
        for c in contenders
    ]
    return rounds_record(loads=loads, hogs=hog, duration_s=duration, rounds=rounds, rows=rows, ratios=ratios(rows))


def ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The target ratios of medians, where both contenders were measured; then
    the same pairs' CPU cost per step, inverted so that > 1 means "cheaper"."""
    median = {(r["name"], r["num_envs"]): r["median"] for r in rows}
    cpu = {(r["name"], r["num_envs"]): r["cpu_us_per_step"] for r in rows}
    out = []
    for what, num, den, n, target in TARGETS:
        a, b = median.get((num, n)), median.get((den, n))
        if a and b:
            out.append({"ratio": f"{what}, N={n}", "value": a / b, "target": target})
    for what, num, den, n, _ in TARGETS:
        a, b = cpu.get((num, n)), cpu.get((den, n))
        if a and b:
            out.append({"ratio": f"CPU/step: {what}, N={n}", "value": b / a, "target": None})
    return out


def format_table(result: dict[str, Any]) -> str:
    lines = [f"{'contender':22s} {'N':>3s} {'median steps/s':>15s} {'CPU us/step':>12s}   rounds (steps/s)"]
    for r in result["rows"]:
        rounds = " ".join(f"{x:.0f}" for x in r["rates"])
        lines.append(
            f"{r['name']:22s} {r['num_envs']:>3d} {r['median']:>15.0f} {r['cpu_us_per_step']:>12.1f}   {rounds}"
        )
    lines += ["", f"{'ratio of medians (> 1: numerator better)':48s} {'value':>6s} {'target':>10s}"]
    for r in result["ratios"]:
        target = (
            "" if r["target"] is None else f">={r['target']:.1f} {'met' if r['value'] >= r['target'] else 'MISSED'}"
        )
        lines.append(f"{r['ratio']:48s} {r['value']:6.2f} {target:>10s}")
    m = result["machine"]
    loads = ", ".join(f"{x:.2f}" for x in result["load_avg_per_round"])
    lines += [
        "",
        f"{result['date']}; {m['cpus']} CPUs, {m['platform']}, Python {m['python']}; "
        f"{result['rounds']} rounds x {result['duration_s']:g} s per contender; CPU hogs: {result['hogs']}; "
        f"load average after each round: {loads}",
    ]
    return "\n".join(lines)


def format_profile(ns: list[int]) -> str:
    """The stage profile (:func:`remoteenv.benchmarks.harness.step_profile.profile`) of each N, as a table."""
    from remoteenv.benchmarks.harness.step_profile import STAGES, profile

    by_n = {n: profile(n) for n in ns}
    head = "".join(f"{f'N={n} wall':>12s}{f'N={n} CPU':>12s}" for n in ns)
    lines = [f"{'stage (microseconds per vector step)':40s}{head}"]
    for stage in STAGES:
        lines.append(f"{stage:40s}" + "".join(f"{by_n[n][0][stage]:12.1f}{by_n[n][1][stage]:12.1f}" for n in ns))
    totals = {n: (sum(by_n[n][0].values()), sum(by_n[n][1].values())) for n in ns}
    lines.append(f"{'total':40s}" + "".join(f"{totals[n][0]:12.1f}{totals[n][1]:12.1f}" for n in ns))
    lines.append(f"{'total per world':40s}" + "".join(f"{totals[n][0] / n:12.2f}{totals[n][1] / n:12.2f}" for n in ns))
    lines.append("")
    lines.append(format_reply_profile(ns))
    lines.append(f"load average {os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M %Z')}")
    return "\n".join(lines)


def format_reply_profile(ns: list[int]) -> str:
    """The sim's reply to a step that starts episodes, world by world and from the arrays
    (:func:`remoteenv.benchmarks.harness.reply_profile.reply_profile`), for each N, as a table."""
    from remoteenv.benchmarks.harness.reply_profile import CASES, reply_profile

    by_n = {n: reply_profile(n) for n in ns}
    head = "".join(f"{f'N={n} per world':>16s}{f'N={n} arrays':>14s}{'ratio':>7s}" for n in ns)
    lines = [f"{'sim: build and pack the reply (microseconds)':44s}{head}"]
    for case in CASES:
        cells = "".join(
            f"{by_n[n][case][0]:16.1f}{by_n[n][case][1]:14.1f}{by_n[n][case][1] / by_n[n][case][0]:7.2f}" for n in ns
        )
        lines.append(f"{case:44s}{cells}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    try:
        ns = [int(x) for x in args.batched_n.split(",") if x.strip()]
    except ValueError:
        raise SystemExit(f"--batched-n must be comma-separated integers, got {args.batched_n!r}") from None
    if not ns or min(ns) < 2:
        raise SystemExit(f"--batched-n must be integers >= 2, got {args.batched_n!r}")
    if args.batched_duration <= 0 or args.rounds < 1 or args.hog < 0:
        raise SystemExit("--batched-duration must be > 0 s, --rounds >= 1 and --hog >= 0")
    if args.profile:
        print(format_profile(ns))
        return 0
    log = progress_log(args.json)
    result = measure(ns, args.batched_duration, args.rounds, args.hog, log=log, heavy=not args.no_heavy)
    emit(result, args.json, format_table)
    return 0
