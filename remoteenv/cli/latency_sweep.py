"""``python -m remoteenv latency-sweep``: a policy's return across delays, over seeds.

For every delay in --delays and every seed in --seeds it runs --episodes
episodes of the env with a fixed policy and records each episode's return
and length. The policy is a builtin controller or a TorchScript file
(--policy), or a plain Python controller (--controller module:function, or
a .py file, optionally file.py:function, default name "policy"): a function
from observation to action, or a class whose no-argument instance is one; a
reset() method, if it has one, is called at each episode's start.
--mode says what a delay of d means:

  action_delay  lock-step, action_delay=d ticks (or, with --random, Uniform(0, d));
  obs_delay     lock-step, obs_delay=d ticks (likewise);
  real_time     real_time=True and the agent thinks d control ticks of wall
                time (d * dt seconds) before each action, so the latency the
                world sees is about d ticks plus the real one (the measured
                mean is reported as latency_ticks).

Lock-step runs repeat exactly: seed ``s`` seeds the first reset of its run
(scene and delay streams), later episodes continue the streams.

It writes ``sweep.csv`` (one row per episode), ``sweep.json`` (the
configuration, the rows and a summary per delay: mean over seeds of each
seed's mean return, with the spread over seeds) and ``sweep.png`` (mean
return against delay, the band spanning the seeds' means) into ``--out``.
In the lock-step modes each row also has the measured mean age of the
action in force (``info["action_delay_ticks"]`` per tick) and how many of
the episode's actions never took effect (overtaken, or still on their way
when it ended); the printed table gives both per delay (mean age per tick,
fraction of the actions sent).
"""

from __future__ import annotations

import argparse
import csv
import importlib
import importlib.util
import io
import json
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from remoteenv.cli.arguments import MAX_SEED, json_map, non_negative_int, positive_int
from remoteenv.cli.optional import require
from remoteenv.wire.files.file_reads import read_bytes

#: Builtin controllers (functions of remoteenv.controllers) and the scene each suits.
BUILTIN_POLICIES = {
    "cartpole_continuous": "CartPole with continuous=True",
    "cartpole_discrete": "CartPole (Discrete(2))",
    "reacher_reach": "Reacher",
}
MODES = ("action_delay", "obs_delay", "real_time")
#: Largest TorchScript --policy file read.
MAX_POLICY_BYTES = 1 << 30
CSV_FIELDS = (
    "delay",
    "seed",
    "episode",
    "return",
    "length",
    "latency_ticks",
    "action_age_ticks",
    "actions_never_acted",
)

Policy = Callable[[np.ndarray], Any]


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "latency-sweep",
        help="a policy's return across action/observation delays or real-time think times",
        description="\n\n".join(__doc__.split("\n\n")[1:3]) if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("env", help="a Gymnasium id (remoteenv/CartPole-v0), a shipped scene name or a scene script path")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--policy",
        help=f"a builtin controller ({', '.join(BUILTIN_POLICIES)}) or a TorchScript file "
        "(torch.jit.save of a module mapping a float32 obs batch to an action batch)",
    )
    which.add_argument(
        "--controller",
        help="a plain Python controller: module:function (importable, e.g. remoteenv.controllers:cartpole_continuous) "
        "or a .py file (path.py or path.py:function; default function name 'policy'); a class is instantiated "
        "with no arguments",
    )
    p.add_argument("--delays", default="0,1,2,3,4", help="comma-separated delays in control ticks (default 0..4)")
    p.add_argument("--mode", choices=MODES, default="action_delay", help="what a delay means (default action_delay)")
    p.add_argument("--random", action="store_true", help="lock-step: draw each delay from Uniform(0, d) instead")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes per delay and seed (default 5)")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated seeds (default 0,1,2)")
    p.add_argument("--max-steps", type=positive_int, default=None, help="cut episodes at this many steps")
    p.add_argument(
        "--action-history", type=non_negative_int, default=0, help="wrap in ActionHistory(env, k) (the policy's input)"
    )
    p.add_argument("--env-kwargs", default="{}", help="JSON map for the env, e.g. '{\"continuous\": true}'")
    p.add_argument("--out", default="latency-sweep", help="directory for sweep.csv, sweep.json, sweep.png")
    p.add_argument("--no-plot", action="store_true", help="skip the plot (no matplotlib needed)")
    p.set_defaults(run=run)


def int_list(text: str, what: str, maximum: int | None = None) -> list[int]:
    """Comma-separated integers in ``0..maximum`` (one line naming ``what`` if not)."""
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"{what} must be comma-separated integers, got {text[:80]!r}") from None
    if not values or min(values) < 0:
        raise SystemExit(f"{what} must hold at least one integer >= 0, got {text[:80]!r}")
    if maximum is not None and max(values) > maximum:
        raise SystemExit(f"{what} must be integers in 0..{maximum}, got {str(max(values))[:40]}")
    return values


def load_policy(name: str) -> Policy:
    """A builtin controller by name, or a TorchScript module from a file (run on CPU, no grad)."""
    if name in BUILTIN_POLICIES:
        from remoteenv import controllers

        fn: Policy = getattr(controllers, name)
        return fn
    if not os.path.isfile(name):
        raise SystemExit(f"--policy {name[:200]!r} is neither a builtin ({', '.join(BUILTIN_POLICIES)}) nor a file")
    torch = require("torch", "a TorchScript --policy")
    try:
        data = read_bytes(name, MAX_POLICY_BYTES, what="--policy")
        module = torch.jit.load(io.BytesIO(data), map_location="cpu")
    except (OSError, ValueError, RuntimeError) as exc:  # UnreadableFile is a ValueError; torch says RuntimeError
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise SystemExit(f"--policy {name[:200]!r} is not a TorchScript file (torch.jit.save): {first}") from None
    module.eval()

    def policy(obs: np.ndarray) -> Any:
        with torch.no_grad():
            out = module(torch.as_tensor(np.asarray(obs, dtype=np.float32)).unsqueeze(0))
        return out.squeeze(0).numpy()

    return policy


def load_controller(spec: str) -> Policy:
    """A plain Python controller: ``module:function`` or ``file.py[:function]``
    (see the module docs); a one-line SystemExit naming ``spec`` if it cannot be had."""
    where, _, name = spec.rpartition(":") if ":" in spec else (spec, "", "")
    if where.endswith(".py") or spec.endswith(".py"):
        path = where if where.endswith(".py") else spec
        name = (name if where.endswith(".py") else "") or "policy"
        if not os.path.isfile(path):
            raise SystemExit(f"--controller: {path[:200]!r} is not a file")
        module_spec = importlib.util.spec_from_file_location(f"remoteenv_controller_{abs(hash(path))}", path)
        if module_spec is None or module_spec.loader is None:
            raise SystemExit(f"--controller: cannot load {path[:200]!r} as Python")
        module = importlib.util.module_from_spec(module_spec)
        try:
            module_spec.loader.exec_module(module)
        except Exception as exc:  # the user's file raised while loading
            raise SystemExit(f"--controller: {path[:200]!r} raised {type(exc).__name__}: {str(exc)[:200]}") from None
        where = path
    else:
        if not where or not name:
            raise SystemExit(f"--controller must be module:function or a .py file, got {spec[:200]!r}")
        try:
            module = importlib.import_module(where)
        except ImportError as exc:
            raise SystemExit(f"--controller: cannot import {where[:200]!r}: {str(exc)[:200]}") from None
    target = getattr(module, name, None)
    if target is None:
        raise SystemExit(f"--controller: {where[:200]!r} has no {name[:100]!r}")
    if isinstance(target, type):
        try:
            target = target()
        except Exception as exc:
            raise SystemExit(f"--controller: {name[:100]}() raised {type(exc).__name__}: {str(exc)[:200]}") from None
    if not callable(target):
        raise SystemExit(f"--controller: {where[:200]}:{name[:100]} is not callable (observation -> action)")
    fn: Policy = target
    return fn


def make_env(args: argparse.Namespace, delay: int) -> Any:
    """The env of one point of the sweep."""
    import gymnasium as gym

    import remoteenv
    from remoteenv.delays import Uniform
    from remoteenv.wrappers import ActionHistory

    kwargs = json_map(args.env_kwargs, "--env-kwargs")
    spec: Any = Uniform(0, delay) if args.random else delay
    if args.mode == "action_delay":
        kwargs["action_delay"] = spec
    elif args.mode == "obs_delay":
        kwargs["obs_delay"] = spec
    else:
        kwargs["real_time"] = True
    if args.max_steps is not None:
        kwargs["max_episode_steps"] = args.max_steps
    target = args.env
    if target in remoteenv.SHIPPED_SCENES:
        target = remoteenv.SHIPPED_SCENES[target]
    if os.path.isfile(target):
        env: Any = remoteenv.OpenAIRemoteEnv(target, **{k: v for k, v in kwargs.items() if k != "max_episode_steps"})
        if args.max_steps is not None:
            env = gym.wrappers.TimeLimit(env, args.max_steps)
    else:
        env = gym.make(target, **kwargs)
    if args.action_history:
        env = ActionHistory(env, args.action_history)
    return env


def run_point(env: Any, policy: Policy, seed: int, episodes: int, think_s: float) -> list[dict[str, Any]]:
    """``episodes`` episodes from ``reset(seed=seed)``; one row per episode."""
    rows = []
    reset = getattr(policy, "reset", None)
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed if episode == 0 else None)
        if callable(reset):
            reset()
        total, length, latencies, ages, acted = 0.0, 0, [], [], 0
        done = False
        while not done:
            if think_s:
                time.sleep(think_s)
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            total += float(reward)
            length += 1
            if info.get("latency_ticks") is not None:
                latencies.append(float(info["latency_ticks"]))
            if info.get("action_delay_ticks") is not None:  # delayed lock-step: the action in force
                ages.append(float(info["action_delay_ticks"]))
                acted += info.get("action_took_effect") is True
            done = terminated or truncated
        rows.append(
            {
                "seed": seed,
                "episode": episode,
                "return": total,
                "length": length,
                "latency_ticks": float(np.mean(latencies)) if latencies else 0.0,
                # the mean age of the action in force, and the actions that never took effect
                # (overtaken, or still on their way at the end); empty without a lock-step delay
                "action_age_ticks": float(np.mean(ages)) if ages else None,
                "actions_never_acted": len(ages) - acted if ages else None,
            }
        )
    return rows


def summarize(rows: list[dict[str, Any]], delays: list[int], seeds: list[int]) -> list[dict[str, Any]]:
    """Per delay: each seed's mean return, their mean, std, min and max, and the mean latency."""
    out = []
    for d in delays:
        per_seed = [float(np.mean([r["return"] for r in rows if r["delay"] == d and r["seed"] == s])) for s in seeds]
        lat = [r["latency_ticks"] for r in rows if r["delay"] == d]
        measured = [r for r in rows if r["delay"] == d and r.get("action_age_ticks") is not None]
        steps = sum(r["length"] for r in measured)
        out.append(
            {
                "delay": d,
                "mean_return": float(np.mean(per_seed)),
                "std_over_seeds": float(np.std(per_seed)),
                "min_over_seeds": float(np.min(per_seed)),
                "max_over_seeds": float(np.max(per_seed)),
                "seed_means": per_seed,
                "mean_latency_ticks": float(np.mean(lat)),
                # per tick over every episode of the point (None without a lock-step delay)
                "mean_action_age_ticks": (
                    sum(r["action_age_ticks"] * r["length"] for r in measured) / steps if steps else None
                ),
                "never_acted_fraction": sum(r["actions_never_acted"] for r in measured) / steps if steps else None,
            }
        )
    return out


def plot(summary: list[dict[str, Any]], path: str, title: str, xlabel: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [s["delay"] for s in summary]
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    ax.plot(x, [s["mean_return"] for s in summary], marker="o", label="mean over seeds")
    ax.fill_between(
        x,
        [s["min_over_seeds"] for s in summary],
        [s["max_over_seeds"] for s in summary],
        alpha=0.25,
        label="spread of the seeds' means",
    )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("episode return")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


class SweepFiles:
    """The sweep's result files in ``out``: ``sweep.csv`` is created (and its
    header written) before the sweep starts, so an unwritable ``out`` fails at
    once, and takes each episode's row as soon as it ends; ``sweep.json`` is
    rewritten after every delay point. A sweep cut short keeps what it ran."""

    def __init__(self, out: str) -> None:
        self.out = out
        self.csv_path = os.path.join(out, "sweep.csv")
        self.json_path = os.path.join(out, "sweep.json")
        try:
            os.makedirs(out, exist_ok=True)
            fd = os.open(self.csv_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0), 0o644)
        except OSError as exc:
            raise SystemExit(f"cannot write the results into --out {out!r}: {exc.strerror or exc}") from None
        self._csv = os.fdopen(fd, "w", newline="")
        self._writer = csv.DictWriter(self._csv, fieldnames=CSV_FIELDS)
        self._writer.writeheader()
        self._csv.flush()

    def add(self, row: dict[str, Any]) -> None:
        """Append one episode's row to ``sweep.csv`` (flushed at once)."""
        self._writer.writerow(row)
        self._csv.flush()

    def write_json(self, doc: dict[str, Any]) -> None:
        """Replace ``sweep.json`` with ``doc`` (atomically)."""
        from remoteenv.wire.files.files import write_atomic

        write_atomic(self.json_path, json.dumps(doc, indent=1))

    def close(self) -> None:
        self._csv.close()


def checked_env(args: argparse.Namespace, delay: int) -> Any:
    """:func:`make_env`, its errors about the arguments (an unknown id, keyword
    arguments the scene does not take, a scene that fails to start) one line."""
    import gymnasium as gym

    from remoteenv.agent.errors import RemoteEnvError

    try:
        return make_env(args, delay)
    except (gym.error.Error, ModuleNotFoundError, RemoteEnvError, TypeError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:300]
        raise SystemExit(f"latency-sweep: cannot make {args.env[:200]!r}: {first}") from None


def run(args: argparse.Namespace) -> int:
    from remoteenv.delays import MAX_DELAY_TICKS

    delays = int_list(args.delays, "--delays", MAX_DELAY_TICKS)
    seeds = int_list(args.seeds, "--seeds", MAX_SEED)
    if args.action_history > MAX_DELAY_TICKS:
        raise SystemExit(f"--action-history must be within 0..{MAX_DELAY_TICKS} (the most actions in flight)")
    if args.action_history and args.policy in BUILTIN_POLICIES:
        raise SystemExit(
            "--action-history changes the observation; the builtin controllers take the env's own: "
            "use it with a TorchScript --policy or a --controller"
        )
    if args.episodes < 1:
        raise SystemExit("--episodes must be >= 1")
    if args.max_steps is not None and args.max_steps < 1:
        raise SystemExit("--max-steps must be a positive integer")
    if args.random and args.mode == "real_time":
        raise SystemExit("--random applies to the lock-step modes; real_time's think time is fixed per point")
    json_map(args.env_kwargs, "--env-kwargs")
    if not args.no_plot:
        require("matplotlib", "latency-sweep's plot (or pass --no-plot)")
    policy = load_policy(args.policy) if args.policy is not None else load_controller(args.controller)
    files = SweepFiles(args.out)  # before the first sim starts
    first_env = checked_env(args, delays[0])  # a bad id or keyword fails here, in one line
    config = {k: v for k, v in vars(args).items() if k != "run"}
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    try:
        with progress(len(delays) * len(seeds) * args.episodes) as bar:
            for i, d in enumerate(delays):
                env = first_env if i == 0 else checked_env(args, d)
                try:
                    think = d * float(env.unwrapped.dt) if args.mode == "real_time" else 0.0
                    for s in seeds:
                        for row in run_point(env, policy, s, args.episodes, think):
                            rows.append({"delay": d, **row})
                            files.add(rows[-1])
                            bar.update(1)
                finally:
                    env.close()
                done = delays[: i + 1]
                doc = {"config": config, "wall_s": time.perf_counter() - started, "complete": done == delays}
                files.write_json({**doc, "summary": summarize(rows, done, seeds), "rows": rows})
    finally:
        files.close()
    wall = time.perf_counter() - started
    summary = summarize(rows, delays, seeds)
    kind = f"Uniform(0, d) {args.mode}" if args.random else args.mode
    xlabel = "think time d (ticks)" if args.mode == "real_time" else f"{kind} d (ticks)"
    if not args.no_plot:
        plot(
            summary,
            os.path.join(args.out, "sweep.png"),
            f"{args.env}, {args.policy or args.controller}: {kind}",
            xlabel,
        )
    print(
        f"{'delay':>5}  {'mean return':>11}  {'std (seeds)':>11}  {'latency ticks':>13}  "
        f"{'action age':>10}  {'never acted':>11}"
    )
    for point in summary:
        age, never = point["mean_action_age_ticks"], point["never_acted_fraction"]
        print(
            f"{point['delay']:5d}  {point['mean_return']:11.2f}  {point['std_over_seeds']:11.2f}  "
            f"{point['mean_latency_ticks']:13.2f}  {'-' if age is None else f'{age:10.2f}':>10}  "
            f"{'-' if never is None else f'{never:11.3f}':>11}"
        )
    print(f"wrote {files.csv_path}, sweep.json{'' if args.no_plot else ', sweep.png'} in {wall:.1f} s")
    return 0


class _Lines:
    """A stand-in for tqdm's bar when tqdm is not installed: one line per tenth."""

    def __init__(self, total: int) -> None:
        self.total, self.done = total, 0

    def __enter__(self) -> _Lines:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def update(self, n: int) -> None:
        step = max(1, self.total // 10)
        before, self.done = self.done, self.done + n
        if before // step != self.done // step or self.done == self.total:
            print(f"latency sweep: {self.done}/{self.total} episodes", flush=True)


def progress(total: int) -> Any:
    """A progress bar over ``total`` episodes: tqdm's if installed (it is optional), else plain lines."""
    try:
        from tqdm import tqdm
    except ModuleNotFoundError:
        return _Lines(total)
    return tqdm(total=total, unit="episode", desc="latency sweep")
