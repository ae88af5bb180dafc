"""``python -m remoteenv bench --train-loop``: the envs inside a PPO-shaped training loop.

Agent side; it starts one training process per contender and N
(:mod:`remoteenv.benchmarks.train_loop_worker`), each with its learner on the
same CPUs as its envs, as a user's training script runs: every vector step a
2x64 tanh MLP infers the actions of all N Reacher worlds; every 128 vector
steps, 4 epochs of SGD on the batch in 4 minibatches
(:class:`~remoteenv.benchmarks.harness.ppo_shaped_learner.PPOShapedLearner`); torch's
settings as the process has them (``--train-env KEY=VALUE`` sets environment
variables of every training process, e.g. ``OMP_NUM_THREADS=1``, to measure a
lever). Contenders: remoteenv's default vector env of ``remoteenv/Reacher-v0``,
EnvPool's ``Reacher-v5`` (skipped with a note when EnvPool is not installed:
``pip install 'remoteenv[bench]'``), Gymnasium's ``SyncVectorEnv`` and
``AsyncVectorEnv`` of ``Reacher-v5``, and ``process-floor``: the
floor under remoteenv's lock-step lane, its layout and scene stepping with a
bare hand-off (:mod:`remoteenv.benchmarks.harness.process_floor`), and, when asked for,
``agent-floor``: remoteenv's sims under a bare agent end
(:mod:`remoteenv.benchmarks.harness.agent_floor`), which splits the lane's cost
between its two ends, and ``waits-floor``: bare ends that wait as remoteenv's
lane does (:mod:`remoteenv.benchmarks.harness.waits_floor`), the floor under
the lane's own work. All are built first (one at a time),
then timed in alternating rounds of whole rollout-and-update iterations, so
load that comes and goes hits them alike. Each row gives steps per wall
second (env steps, learning included), CPU microseconds per step of the
training process and everything it started, context switches per step, and
where the trainer's wall time went (policy inference, env step, update). It
measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable
from typing import IO, Any

from remoteenv.benchmarks.harness.anchors import CpuHog
from remoteenv.benchmarks.harness.host_speed import FULL_SPEED, HostSpeed
from remoteenv.benchmarks.harness.host_steal import HostSteal
from remoteenv.benchmarks.harness.loop_plot import plot_train_loop
from remoteenv.benchmarks.harness.paired_interval import CONFIDENCE, paired_interval, settled
from remoteenv.benchmarks.harness.report import emit, progress_log, rounds_record
from remoteenv.benchmarks.train_loop_worker import CONTENDERS, DEFAULT_CONTENDERS
from remoteenv.wire.files.file_reads import read_text

#: (numerator, denominator, N, target) of the ratios of medians reported.
TARGETS = [
    ("remoteenv", "EnvPool", 16, 1.0),
    ("remoteenv", "EnvPool", 64, 1.0),
    ("remoteenv", "SyncVectorEnv", 16, 1.5),
    ("remoteenv", "SyncVectorEnv", 64, None),
    ("remoteenv", "AsyncVectorEnv", 16, None),
    ("remoteenv", "AsyncVectorEnv", 64, None),
    ("remoteenv", "process-floor", 16, None),
    ("remoteenv", "process-floor", 64, None),
    ("process-floor", "EnvPool", 16, None),
    ("process-floor", "EnvPool", 64, None),
    ("remoteenv", "agent-floor", 16, None),
    ("remoteenv", "agent-floor", 64, None),
    ("agent-floor", "process-floor", 16, None),
    ("agent-floor", "process-floor", 64, None),
    ("remoteenv", "waits-floor", 16, None),
    ("remoteenv", "waits-floor", 64, None),
    ("waits-floor", "process-floor", 16, None),
    ("waits-floor", "process-floor", 64, None),
    ("waits-floor", "EnvPool", 16, None),
    ("waits-floor", "EnvPool", 64, None),
    ("waits-floor", "SyncVectorEnv", 16, None),
]
#: A slot whose host held at least this share of the CPUs' time is counted in the report's steal line,
#: and its round is not one at full speed (:func:`full_speed_rounds`).
STEAL_NOTED = 0.05
#: Longest a contender may take to build and warm up, or to answer a round beyond its length (seconds).
_PATIENCE_S = 300.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("training-loop benchmark (--train-loop)")
    g.add_argument("--train-n", default="16,64", help="comma-separated vector sizes N (default 16,64)")
    g.add_argument("--train-rounds", type=int, default=5, help="alternating rounds; medians are shown (default 5)")
    g.add_argument(
        "--train-duration",
        type=float,
        default=3.0,
        help="seconds per contender per round, whole iterations (default 3)",
    )
    g.add_argument(
        "--train-contenders",
        default=",".join(DEFAULT_CONTENDERS),
        help=f"comma-separated contenders, of {', '.join(CONTENDERS)} (default {','.join(DEFAULT_CONTENDERS)}); "
        "remoteenv-torch-kept is remoteenv with torch_threads=None, remoteenv-os-placed with place_sims=None, remoteenv-neither with both; process-floor is remoteenv's layout "
        "and scene stepping with a bare hand-off (the floor under its lane), agent-floor remoteenv's sims under a bare "
        "agent end, waits-floor bare ends that wait as remoteenv's lane does (layout, hot waits, heads-up); NAME:KEY=VALUE runs one with "
        "environment variables of its own (e.g. EnvPool:OMP_NUM_THREADS=1 beside EnvPool)",
    )
    g.add_argument(
        "--train-env",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an environment variable of every training process (repeatable), e.g. OMP_NUM_THREADS=1",
    )
    g.add_argument(
        "--train-plot",
        default=None,
        metavar="PATH",
        help="also draw the result into this image file (.png, .svg; needs matplotlib)",
    )
    g.add_argument(
        "--train-from",
        default=None,
        metavar="JSON",
        help="run nothing: show (and with --train-plot draw) the result an earlier run wrote with --json",
    )


class Trainer:
    """One contender's training process for one N; ``label`` names it in the
    table (the contender, and any environment variables of its own)."""

    def __init__(self, contender: str, num_envs: int, env: dict[str, str], label: str | None = None) -> None:
        self.contender, self.num_envs = label or contender, num_envs
        read_fd, write_fd = os.pipe()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "remoteenv.benchmarks.train_loop_worker", contender, str(num_envs)]
            + ["--out-fd", str(write_fd)],
            stdin=subprocess.PIPE,
            pass_fds=(write_fd,),
            env={**os.environ, **env},
            # ``-m`` puts the working directory first on sys.path: a checkout there
            # (the repository's root) would shadow a contender's own PYTHONPATH.
            cwd=tempfile.gettempdir() if "PYTHONPATH" in env else None,
            text=True,
        )
        os.close(write_fd)
        self.replies: IO[str] = os.fdopen(read_fd)
        self.rounds: list[dict[str, Any]] = []
        self.ready = self._reply()

    def _reply(self) -> dict[str, Any]:
        line = self.replies.readline()
        if not line:
            raise RuntimeError(f"the {self.contender} training process (N={self.num_envs}) ended without answering")
        reply: dict[str, Any] = json.loads(line)
        return reply

    def run_round(self, duration: float) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"round {duration}\n")
        self.proc.stdin.flush()
        self.rounds.append(self._reply())

    def close(self) -> None:
        if self.proc.stdin is not None and self.proc.poll() is None:
            try:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.close()
            except OSError:
                pass
        try:
            self.proc.wait(_PATIENCE_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.replies.close()


def _row(t: Trainer) -> dict[str, Any]:
    rounds = t.rounds
    steps = sum(r["steps"] for r in rounds)

    def per_step(key: str) -> float:
        return sum(r[key] for r in rounds) / steps

    wall = sum(r["wall_s"] for r in rounds)
    return {
        "name": t.contender,
        "num_envs": t.num_envs,
        "median": statistics.median(r["steps_per_s"] for r in rounds),
        "rates": [r["steps_per_s"] for r in rounds],
        "host_speeds": [r["host_speed"] for r in rounds],
        "host_steals": [r.get("host_steal") for r in rounds],
        "cpu_us_per_step": statistics.median(r["cpu_us_per_step"] for r in rounds),
        "trainer_cpu_us_per_step": per_step("trainer_cpu_s") * 1e6,
        "voluntary_switches_per_step": per_step("voluntary_switches"),
        "involuntary_switches_per_step": per_step("involuntary_switches"),
        "wall_share": {k: sum(r["seconds"][k] for r in rounds) / wall for k in ("act", "env_step", "update")},
        "build_s": t.ready["build_s"],
        "torch_threads": t.ready["torch_threads"],
        "processes": rounds[-1]["processes"] if rounds else None,
    }


def measure(
    ns: list[int],
    contenders: list[str],
    duration: float,
    rounds: int,
    hog: int,
    env: dict[str, str],
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    trainers: list[Trainer] = []
    loads: list[float] = []
    skipped: list[str] = []
    host: HostSpeed | None = None
    try:
        for n in ns:
            for spec in contenders:
                name, own_env = _contender(spec)
                log(f"  building {spec}, N={n}")
                t = Trainer(name, n, {**env, **own_env}, label=spec)
                if "error" in t.ready:
                    log(f"  {t.ready['error']}: its rows are skipped")
                    skipped.append(t.ready["error"])
                    t.close()
                    continue
                trainers.append(t)
        with CpuHog(hog):
            host = HostSpeed()
            steal = HostSteal()
            for r in range(rounds):
                # Each round starts one contender later, so none always follows the same one.
                shift = r % len(trainers)
                for t in trainers[shift:] + trainers[:shift]:
                    steal.start()
                    t.run_round(duration)
                    t.rounds[-1]["host_steal"] = steal.stop()
                    t.rounds[-1]["host_probes"] = host.after_slot()
                loads.append(os.getloadavg()[0])
                log(f"  round {r + 1}/{rounds} done, load average {loads[-1]:.2f}")
        for t in trainers:
            for done in t.rounds:
                done["host_speed"] = host.speed(done.pop("host_probes"))
    finally:
        for t in trainers:
            t.close()
    rows = [_row(t) for t in trainers]
    return rounds_record(
        loads=loads,
        hogs=hog,
        duration_s=duration,
        rounds=rounds,
        train_env=env,
        skipped=skipped,
        host_probe_fastest_s=None if host is None else host.fastest_s,
        rows=rows,
        ratios=ratios(rows),
    )


def ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The ratios of medians of :data:`TARGETS` where both were measured, each
    with its ratio round by round (``rounds``: the two contenders' rates of
    the same round, which ran them one after the other) and, with enough
    rounds, their geometric mean and its interval (``paired``: ``[mean, low,
    high]``, :func:`~remoteenv.benchmarks.harness.paired_interval.paired_interval`;
    None with too few), then their CPU per step inverted (> 1: the numerator
    is cheaper)."""
    by = {(r["name"], r["num_envs"]): r for r in rows}
    out = []
    for num, den, n, target in TARGETS:
        a, b = by.get((num, n)), by.get((den, n))
        if a and b:
            rounds = paired_rounds(a, b)
            interval = paired_interval(rounds)
            full = full_speed_rounds(a, b, rounds)
            full_interval = paired_interval(full)
            out.append(
                {
                    "ratio": f"{num} / {den}, N={n}",
                    "value": a["median"] / b["median"],
                    "target": target,
                    "rounds": rounds,
                    "paired": None if interval is None else list(interval),
                    "full_speed_rounds": full,
                    "paired_full_speed": None if full_interval is None else list(full_interval),
                }
            )
    for num, den, n, _ in TARGETS:
        a, b = by.get((num, n)), by.get((den, n))
        if a and b:
            out.append(
                {
                    "ratio": f"CPU/step: {num} / {den}, N={n}",
                    "value": b["cpu_us_per_step"] / a["cpu_us_per_step"],
                    "target": None,
                }
            )
    return out


def paired_rounds(a: dict[str, Any], b: dict[str, Any]) -> list[float]:
    """Row ``a``'s rate over row ``b``'s in each round, in round order ([]
    when either lacks its rates, they ran a different number of rounds or a
    rate of ``b`` is not positive).

    A round runs every contender once, one after the other, so the two rates
    of one round met the same host; how far these ratios spread shows how
    much of a ratio of medians is the host's drift between rounds."""
    ra, rb = a.get("rates") or [], b.get("rates") or []
    if len(ra) != len(rb) or not all(y > 0 for y in rb):
        return []
    return [x / y for x, y in zip(ra, rb)]


def full_speed_rounds(a: dict[str, Any], b: dict[str, Any], paired: list[float]) -> list[float]:
    """The ratios of ``paired`` (rows ``a`` over ``b``, round by round) of the
    rounds in which both were timed on a host at full speed: probes at
    :data:`~remoteenv.benchmarks.harness.host_speed.FULL_SPEED` or more and,
    where the rows have it, a steal share under :data:`STEAL_NOTED` ([] when
    either row lacks its host speeds)."""
    sa, sb = a.get("host_speeds") or [], b.get("host_speeds") or []
    if not paired or len(sa) != len(paired) or len(sb) != len(paired):
        return []
    ta, tb = a.get("host_steals") or [None] * len(paired), b.get("host_steals") or [None] * len(paired)
    if len(ta) != len(paired) or len(tb) != len(paired):
        ta = tb = [None] * len(paired)
    quiet = [all(x is None or x < STEAL_NOTED for x in pair) for pair in zip(ta, tb)]
    return [x for x, u, v, q in zip(paired, sa, sb, quiet) if min(u, v) >= FULL_SPEED and q]


def _verdict(r: dict[str, Any]) -> str:
    """The target column of ratio ``r``: met or missed by the ratio of medians,
    in how many rounds the round's own ratio met it and, with an interval of
    the rounds' mean, whether that settles it."""
    if r["target"] is None:
        return ""
    verdict = f">={r['target']:.1f} {'met' if r['value'] >= r['target'] else 'MISSED'}"
    paired = r.get("rounds") or []
    if paired:
        verdict += f" ({sum(x >= r['target'] for x in paired)}/{len(paired)} rounds)"
    interval = r.get("paired")
    if interval:
        verdict += f"; by the interval: {settled(tuple(interval), r['target'])}"
    full = r.get("paired_full_speed")
    if full:
        verdict += (
            f"; host at full speed ({len(r['full_speed_rounds'])}/{len(paired)} rounds): "
            f"{_interval_text(full)} {settled(tuple(full), r['target'])}"
        )
    return verdict


def _interval_text(interval: list[float]) -> str:
    """A mean and its interval, as ``mean [low-high]``."""
    return f"{interval[0]:.2f} [{interval[1]:.2f}-{interval[2]:.2f}]"


def _paired(r: dict[str, Any]) -> str:
    """The rounds' geometric mean and its interval (blank without one)."""
    interval = r.get("paired")
    return _interval_text(interval) if interval else ""


def _spread(r: dict[str, Any]) -> str:
    paired = r.get("rounds") or []
    return f"{min(paired):.2f}-{max(paired):.2f}" if paired else ""


def format_table(result: dict[str, Any]) -> str:
    lines = [
        f"{'contender':15s} {'N':>3s} {'steps/s':>8s} {'CPU us/step':>11s} {'trainer':>8s} "
        f"{'vol/step':>8s} {'invol/step':>10s} {'act':>5s} {'step':>5s} {'update':>6s}   rounds (steps/s)"
    ]
    for r in result["rows"]:
        share = r["wall_share"]
        rounds = " ".join(f"{x:.0f}" for x in r["rates"])
        lines.append(
            f"{r['name']:15s} {r['num_envs']:>3d} {r['median']:>8.0f} {r['cpu_us_per_step']:>11.1f} "
            f"{r['trainer_cpu_us_per_step']:>8.1f} {r['voluntary_switches_per_step']:>8.3f} "
            f"{r['involuntary_switches_per_step']:>10.3f} {share['act']:>5.0%} {share['env_step']:>5.0%} "
            f"{share['update']:>6.0%}   {rounds}"
        )
    lines += [
        "",
        "trainer: CPU us per step of the training process alone (its sims or workers excluded); "
        "vol/invol: context switches per step of every thread of the process tree; "
        "act/step/update: shares of the trainer's wall time",
        "",
        f"{'ratio of medians (> 1: numerator better)':44s} {'value':>6s} {'rounds':>9s} {'paired':>16s}   target",
    ]
    for r in result["ratios"]:
        lines.append(f"{r['ratio']:44s} {r['value']:6.2f} {_spread(r):>9s} {_paired(r):>16s}   {_verdict(r)}".rstrip())
    lines.append("rounds: the lowest and highest ratio of one round's two rates (they ran one after the other)")
    lines.append(
        f"paired: the rounds' ratios' geometric mean [its {CONFIDENCE:.0%} bootstrap interval]; a target is "
        "settled by a run when the whole interval is on one side of it"
    )
    lines.append(
        f"host at full speed: the same over the rounds whose two slots both had probes at {FULL_SPEED:.0%} or more "
        f"of the run's fastest (a fixed loop timed on every CPU before and after each slot) and, where measured, "
        f"the host's steal under {STEAL_NOTED:.0%}"
    )
    speeds = [min(r["host_speeds"]) for r in result["rows"] if r.get("host_speeds")]
    if speeds and result.get("host_probe_fastest_s"):
        lines.append(
            f"host speed: the fastest probe {result['host_probe_fastest_s'] * 1e3:.1f} ms (on its slowest CPU); "
            f"the slowest slot ran at {min(speeds):.2f} of it"
        )
    steals = [x for r in result["rows"] for x in r.get("host_steals") or [] if x is not None]
    if steals:
        lines.append(
            f"host steal: the VM's host held {min(steals):.0%}-{max(steals):.0%} of the CPUs' time in a slot "
            f"(/proc/stat; {sum(x >= STEAL_NOTED for x in steals)} of {len(steals)} slots at {STEAL_NOTED:.0%} or more)"
        )
    m = result["machine"]
    loads = ", ".join(f"{x:.2f}" for x in result["load_avg_per_round"])
    extra = " ".join(f"{k}={v}" for k, v in result["train_env"].items())
    lines += [
        "",
        f"{result['date']}; {m['cpus']} CPUs, {m['platform']}, Python {m['python']}; "
        f"{result['rounds']} rounds x {result['duration_s']:g} s per contender; CPU hogs: {result['hogs']}; "
        f"training processes' extra environment: {extra or 'none'}; load average after each round: {loads}",
    ]
    lines += [f"skipped: {s}" for s in result["skipped"]]
    return "\n".join(lines)


def _parse_env(pairs: list[str]) -> dict[str, str]:
    env = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise SystemExit(f"environment variables are given as KEY=VALUE, got {pair[:80]!r}")
        env[key] = value
    return env


def _contender(spec: str) -> tuple[str, dict[str, str]]:
    """``NAME[:KEY=VALUE...]``: the contender and the environment variables of its own process."""
    name, *pairs = spec.split(":")
    return name, _parse_env(pairs)


def run(args: argparse.Namespace) -> int:
    if args.train_plot:
        import matplotlib  # noqa: F401 - missing: say so before the run, not after it
    if args.train_from:
        result = _earlier(args.train_from)
        emit(result, args.json, format_table)
        if args.train_plot:
            plot_train_loop(result, args.train_plot)
        return 0
    try:
        ns = [int(x) for x in args.train_n.split(",") if x.strip()]
    except ValueError:
        raise SystemExit(f"--train-n must be comma-separated integers, got {args.train_n[:80]!r}") from None
    if not ns or min(ns) < 2 or max(ns) > 1024:
        raise SystemExit(f"--train-n must be integers from 2 to 1024, got {args.train_n[:80]!r}")
    contenders = [c.strip() for c in args.train_contenders.split(",") if c.strip()]
    unknown = sorted({_contender(c)[0] for c in contenders} - set(CONTENDERS))
    if unknown or not contenders:
        raise SystemExit(
            f"--train-contenders takes some of {', '.join(CONTENDERS)}; got {args.train_contenders[:80]!r}"
        )
    if not 0 < args.train_duration <= 600 or not 1 <= args.train_rounds <= 1000 or not 0 <= args.hog <= 64:
        raise SystemExit("--train-duration must be in (0, 600] s, --train-rounds in [1, 1000] and --hog in [0, 64]")
    log = progress_log(args.json)
    result = measure(ns, contenders, args.train_duration, args.train_rounds, args.hog, _parse_env(args.train_env), log)
    emit(result, args.json, format_table)
    if args.train_plot:
        plot_train_loop(result, args.train_plot)
    return 0


#: Largest result file --train-from reads.
_MAX_RESULT_BYTES = 16 << 20


def _earlier(path: str) -> dict[str, Any]:
    """The result an earlier run wrote with ``--json``; SystemExit saying what is wrong otherwise."""
    try:
        result = json.loads(read_text(path, _MAX_RESULT_BYTES, what="training-loop result"))
        rows = result["rows"]
        for r in rows:
            float(r["median"]), int(r["num_envs"]), str(r["name"]), [float(x) for x in r["rates"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"--train-from {path[:200]!r} is not a result of --train-loop --json: {exc}"[:400]) from None
    return dict(result)
