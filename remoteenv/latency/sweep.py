"""A policy's return across delays, over seeds: the sweep behind ``python -m remoteenv latency-sweep``.

Runs in the agent process. :class:`SweepEnv` makes the env of one delay
point (what a delay ``d`` means is its ``mode``), :func:`run_sweep` runs
every point and seed with a fixed policy and writes each episode's row as
it ends (:class:`SweepFiles`), :func:`summarize` gives the table per delay
and :func:`plot` its figure. The command line (:mod:`remoteenv.cli.latency_sweep`)
checks its arguments and calls these. What a delay means:

- ``action_delay``: lock-step, ``action_delay=d`` ticks (or, with
  ``random``, ``Uniform(0, d)``);
- ``obs_delay``: lock-step, ``obs_delay=d`` ticks (likewise);
- ``real_time``: ``real_time=True`` and the agent thinks ``d`` control ticks
  of wall time (``d * dt`` seconds) before each action, so the latency the
  world sees is about ``d`` ticks plus the real one (the measured mean is
  reported as ``latency_ticks``).

Lock-step runs repeat exactly: seed ``s`` seeds the first reset of its run
(scene and delay streams), later episodes continue the streams. In the
lock-step modes each row also has the measured mean age of the action in
force (``info["action_delay_ticks"]`` per tick) and how many of the
episode's actions never took effect (overtaken, or still on their way when
it ended).
"""

from __future__ import annotations

import csv
import importlib
import importlib.util
import io
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from remoteenv.scene_controllers.cartpole import cartpole_continuous, cartpole_discrete
from remoteenv.scene_controllers.reacher import reacher_reach
from remoteenv.wire.files.file_reads import read_bytes

#: Builtin controllers (functions of :mod:`remoteenv.scene_controllers`) and the scene each suits.
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


def load_policy(name: str) -> Policy:
    """A builtin controller by name, or a TorchScript module from a file (run on CPU, no grad)."""
    if name in BUILTIN_POLICIES:
        builtin: dict[str, Policy] = {
            "cartpole_continuous": cartpole_continuous,
            "cartpole_discrete": cartpole_discrete,
            "reacher_reach": reacher_reach,
        }
        return builtin[name]
    if not os.path.isfile(name):
        raise SystemExit(f"--policy {name[:200]!r} is neither a builtin ({', '.join(BUILTIN_POLICIES)}) nor a file")
    import torch  # the command line checked it is installed (cli.optional.require)

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
    (see :mod:`remoteenv.cli.latency_sweep`); a one-line SystemExit naming ``spec`` if it cannot be had."""
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


@dataclass(frozen=True)
class SweepEnv:
    """How to make the env of each delay point.

    Attributes:
        env: a Gymnasium id, a shipped scene's name or a scene script's path.
        mode: what a delay means, one of :data:`MODES`.
        random: lock-step: each action's (or observation's) delay is drawn
            from ``Uniform(0, d)`` instead of being ``d``.
        env_kwargs: more keyword arguments of the env.
        max_steps: cut episodes at this many steps (None: the env's own limit).
        action_history: wrap in ``ActionHistory(env, k)`` (0: no wrapper).
    """

    env: str
    mode: str = "action_delay"
    random: bool = False
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    max_steps: int | None = None
    action_history: int = 0

    def make(self, delay: int) -> Any:
        """The env of delay point ``delay`` (ticks)."""
        import gymnasium as gym

        import remoteenv
        from remoteenv.latency.action_history import ActionHistory
        from remoteenv.wire.delays.delay_specs import Uniform

        kwargs = dict(self.env_kwargs)
        spec: Any = Uniform(0, delay) if self.random else delay
        if self.mode == "action_delay":
            kwargs["action_delay"] = spec
        elif self.mode == "obs_delay":
            kwargs["obs_delay"] = spec
        else:
            kwargs["real_time"] = True
        if self.max_steps is not None:
            kwargs["max_episode_steps"] = self.max_steps
        target = self.env
        if target in remoteenv.SHIPPED_SCENES:
            target = remoteenv.SHIPPED_SCENES[target]
        if os.path.isfile(target):
            env: Any = remoteenv.OpenAIRemoteEnv(
                target, **{k: v for k, v in kwargs.items() if k != "max_episode_steps"}
            )
            if self.max_steps is not None:
                env = gym.wrappers.TimeLimit(env, self.max_steps)
        else:
            env = gym.make(target, **kwargs)
        if self.action_history:
            env = ActionHistory(env, self.action_history)
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


def run_sweep(
    make_env: Callable[[int], Any],
    policy: Policy,
    delays: list[int],
    seeds: list[int],
    episodes: int,
    mode: str,
    files: SweepFiles,
    config: dict[str, Any],
) -> tuple[list[dict[str, Any]], float]:
    """Every delay point of ``delays`` (``make_env(d)`` makes its env; in the
    ``real_time`` mode the agent thinks ``d * dt`` wall seconds per step), each
    seed's ``episodes`` episodes; every row goes to ``files`` as it ends and
    ``sweep.json`` (``config``, rows, summary) is rewritten after each point.
    ``make_env(delays[0])`` is called first, before anything runs. Returns the
    rows and the wall seconds they took (from the first env made)."""
    first_env = make_env(delays[0])  # a bad id or keyword fails here, before anything runs
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    try:
        with progress(len(delays) * len(seeds) * episodes) as bar:
            for i, d in enumerate(delays):
                env = first_env if i == 0 else make_env(d)
                try:
                    think = d * float(env.unwrapped.dt) if mode == "real_time" else 0.0
                    for s in seeds:
                        for row in run_point(env, policy, s, episodes, think):
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
    return rows, time.perf_counter() - started


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
        from remoteenv.wire.files.safe_writes import write_atomic

        write_atomic(self.json_path, json.dumps(doc, indent=1))

    def close(self) -> None:
        self._csv.close()


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


__all__ = [
    "BUILTIN_POLICIES",
    "CSV_FIELDS",
    "MAX_POLICY_BYTES",
    "MODES",
    "Policy",
    "SweepEnv",
    "SweepFiles",
    "load_policy",
    "plot",
    "progress",
    "load_controller",
    "run_point",
    "run_sweep",
    "summarize",
]
