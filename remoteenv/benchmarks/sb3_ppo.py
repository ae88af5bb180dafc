"""``python -m remoteenv bench --sb3``: Stable-Baselines3 PPO on remote CartPole
next to the same PPO on SB3's own vector envs of Gymnasium's CartPole-v1.

Agent side; it launches sims. One PPO (``PPO("MlpPolicy")`` with rl-zoo's
CartPole-v1 hyperparameters, :data:`HYPERPARAMS`, the same seed) trains on
each contender in turn, round-robin, for ``--sb3-rounds`` rounds of
``--sb3-steps`` timesteps:

- ``SubprocVecEnv``: SB3's worker processes, 8 x ``gymnasium.make("CartPole-v1")``;
- ``remoteenv``: :func:`remoteenv.integrations.sb3.make_sb3_vec_env` of ``remoteenv/CartPole-v0``
  (the discrete scene with CartPole-v1's constants and 500-step limit);
- ``DummyVecEnv``: 8 in-process CartPole-v1, a reference row.

Every contender is wrapped in SB3's ``VecMonitor`` (episode returns for
``model.ep_info_buffer``) and a timer of ``env.step``. Each run reports the
wall seconds of ``learn()``, split into rollout collection (between SB3's
``on_rollout_start`` and ``on_rollout_end``: env steps plus policy inference),
``train()`` (the gradient updates), and the rest (logging, bookkeeping); env
steps per second during rollouts; the final mean episode return; the CPU
seconds of this process and every process below it. Torch's thread count is
left as SB3 leaves it and is the same for every contender. The ratios of
issue 13's target are of medians over rounds. It measures and prints; it
asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

from remoteenv.benchmarks.harness.anchors import cpu_seconds
from remoteenv.benchmarks.harness.report import emit, machine_record, progress_log

GYM_ID = "CartPole-v1"
REMOTE_ID = "remoteenv/CartPole-v0"
NUM_ENVS = 8
#: rl-zoo's ``hyperparams/ppo.yml`` for CartPole-v1 (n_envs 8, 1e5 timesteps);
#: ``lin_X`` there is a rate falling linearly from X to 0 over training.
HYPERPARAMS: dict[str, Any] = {
    "n_steps": 32,
    "batch_size": 256,
    "gae_lambda": 0.8,
    "gamma": 0.98,
    "n_epochs": 20,
    "ent_coef": 0.0,
    "learning_rate": ("linear", 1e-3),
    "clip_range": ("linear", 0.2),
}
#: Contenders in the order each round runs them.
CONTENDERS = ("SubprocVecEnv", "remoteenv", "DummyVecEnv")
#: The target of issue 13: remoteenv's learn() wall time / SubprocVecEnv's.
TARGET = 0.5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("SB3 PPO benchmark (--sb3)")
    g.add_argument(
        "--sb3-steps", type=int, default=100_000, help="PPO timesteps per contender per round (default 100000)"
    )
    g.add_argument(
        "--sb3-rounds",
        type=int,
        default=1,
        help="round-robin rounds over the contenders; medians are compared (default 1)",
    )
    g.add_argument("--sb3-seed", type=int, default=0, help="seed of PPO and of the envs (default 0)")


# ---------------------------------------------------------------- measuring


def _linear(initial: float) -> Callable[[float], float]:
    """rl-zoo's ``lin_<initial>``: SB3 passes the progress remaining, 1 -> 0."""
    return lambda progress_remaining: progress_remaining * initial


def ppo_kwargs(seed: int) -> dict[str, Any]:
    """Keyword arguments of ``PPO("MlpPolicy", env, ...)``: :data:`HYPERPARAMS`
    with the schedules built, the seed, CPU, quiet."""
    out: dict[str, Any] = {}
    for key, value in HYPERPARAMS.items():
        out[key] = _linear(value[1]) if isinstance(value, tuple) else value
    return {**out, "seed": seed, "device": "cpu", "verbose": 0}


def make_venv(name: str) -> Any:
    """The contender ``name``'s SB3 ``VecEnv`` of :data:`NUM_ENVS` CartPoles, wrapped in ``VecMonitor``."""
    import gymnasium as gym
    from gymnasium.spaces import Box, Discrete
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor

    if name == "remoteenv":
        from remoteenv.integrations.sb3 import make_sb3_vec_env

        venv: Any = make_sb3_vec_env(REMOTE_ID, NUM_ENVS)
        if not (isinstance(venv.action_space, Discrete) and venv.action_space.n == 2):
            venv.close()
            raise RuntimeError(f"{REMOTE_ID} must be discrete like {GYM_ID}; its action space is {venv.action_space}")
    else:
        cls = {"SubprocVecEnv": SubprocVecEnv, "DummyVecEnv": DummyVecEnv}[name]
        venv = cls([lambda: gym.make(GYM_ID)] * NUM_ENVS)
    assert isinstance(venv.observation_space, Box) and venv.observation_space.shape == (4,)
    return VecMonitor(venv)


def run_once(name: str, steps: int, seed: int) -> dict[str, Any]:
    """Build contender ``name``, train PPO on it for ``steps`` timesteps, close it;
    the run's figures (seconds are wall seconds unless named CPU)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class StepTimer(VecEnvWrapper):
        """Adds up the seconds spent in the wrapped env's ``step``."""

        seconds = 0.0

        def reset(self) -> Any:
            return self.venv.reset()

        def step_wait(self) -> Any:
            start = time.perf_counter()
            out = self.venv.step_wait()
            self.seconds += time.perf_counter() - start
            return out

        def step_async(self, actions: Any) -> None:
            start = time.perf_counter()
            self.venv.step_async(actions)
            self.seconds += time.perf_counter() - start

    class RolloutTimer(BaseCallback):
        """Adds up the seconds between SB3's rollout start and end."""

        seconds = 0.0
        _start = 0.0

        def _on_rollout_start(self) -> None:
            self._start = time.perf_counter()

        def _on_rollout_end(self) -> None:
            self.seconds += time.perf_counter() - self._start

        def _on_step(self) -> bool:
            return True

    threads = torch.get_num_threads()
    start = time.perf_counter()
    venv = StepTimer(make_venv(name))
    try:
        model = PPO("MlpPolicy", venv, **ppo_kwargs(seed))
        setup = time.perf_counter() - start
        train_seconds = 0.0
        train = model.train

        def timed_train() -> None:
            nonlocal train_seconds
            t0 = time.perf_counter()
            train()
            train_seconds += time.perf_counter() - t0

        model.train = timed_train  # type: ignore[method-assign]
        timer = RolloutTimer()
        cpu0 = cpu_seconds()
        t0 = time.perf_counter()
        model.set_logger(Logger(None, []))  # SB3's default logger makes a /tmp/SB3-<time> folder
        model.learn(steps, callback=timer)
        total = time.perf_counter() - t0
        cpu = cpu_seconds() - cpu0  # before close: the workers still count
        returns = [float(ep["r"]) for ep in model.ep_info_buffer or ()]
    finally:
        venv.close()
    return {
        "contender": name,
        "timesteps": int(model.num_timesteps),
        "setup_s": setup,
        "total_s": total,
        "rollout_s": timer.seconds,
        "env_step_s": venv.seconds,
        "train_s": train_seconds,
        "other_s": total - timer.seconds - train_seconds,
        "ppo_own_s": total - venv.seconds,
        "rollout_steps_per_s": model.num_timesteps / timer.seconds if timer.seconds > 0 else 0.0,
        "mean_return": statistics.fmean(returns) if returns else None,
        "episodes_in_mean": len(returns),
        "cpu_s": cpu,
        "torch_threads": threads,
    }


def measure(
    steps: int,
    rounds: int,
    seed: int = 0,
    contenders: tuple[str, ...] = CONTENDERS,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train on every contender, round-robin, ``rounds`` times ``steps`` timesteps;
    the runs, each contender's medians and the ratios (see :func:`summarize`)."""
    import stable_baselines3
    import torch

    runs: list[dict[str, Any]] = []
    loads: list[float] = []
    for r in range(rounds):
        for name in contenders:
            log(f"  round {r + 1}/{rounds}: {name} ...")
            runs.append({"round": r + 1, **run_once(name, steps, seed)})
            last = runs[-1]
            log(f"    {last['total_s']:.1f} s (rollouts {last['rollout_s']:.1f} s, train {last['train_s']:.1f} s)")
        loads.append(os.getloadavg()[0])
    return {
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
        "machine": machine_record(),
        "versions": {"stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__},
        "torch_threads": torch.get_num_threads(),
        "load_avg_per_round": loads,
        "steps": steps,
        "rounds": rounds,
        "seed": seed,
        "num_envs": NUM_ENVS,
        "hyperparams": {k: list(v) if isinstance(v, tuple) else v for k, v in HYPERPARAMS.items()},
        "runs": runs,
        **summarize(runs),
    }


def summarize(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each contender's medians over rounds; the ratios remoteenv / SubprocVecEnv,
    remoteenv / DummyVecEnv and DummyVecEnv / SubprocVecEnv (what no IPC at all
    would give) of learn() wall, rollout and CPU seconds; and the share
    of SubprocVecEnv's learn() wall time its ``train()`` took: a share above
    :data:`TARGET` means no env can meet the target (see :func:`verdict`)."""
    medians: dict[str, dict[str, float]] = {}
    for name in dict.fromkeys(run["contender"] for run in runs):
        mine = [run for run in runs if run["contender"] == name]
        medians[name] = {
            key: statistics.median(run[key] for run in mine)
            for key in ("total_s", "rollout_s", "env_step_s", "train_s", "ppo_own_s", "rollout_steps_per_s", "cpu_s")
        }
    ratios = []
    pairs = [("remoteenv", "SubprocVecEnv"), ("remoteenv", "DummyVecEnv"), ("DummyVecEnv", "SubprocVecEnv")]
    for num, den in pairs:
        if num not in medians or den not in medians:
            continue
        for key, what in (("total_s", "learn() wall"), ("rollout_s", "rollout"), ("cpu_s", "CPU")):
            target = TARGET if (num, den, key) == ("remoteenv", "SubprocVecEnv", "total_s") else None
            value = medians[num][key] / medians[den][key]
            ratios.append({"ratio": f"{num} / {den}, {what}", "value": value, "target": target})
    train_share = floor_share = None
    if "SubprocVecEnv" in medians:
        sub = medians["SubprocVecEnv"]
        train_share = sub["train_s"] / sub["total_s"]
        floor_share = min(m["ppo_own_s"] for m in medians.values()) / sub["total_s"]
    return {
        "medians": medians,
        "ratios": ratios,
        "subproc_train_share": train_share,
        "ppo_floor_share": floor_share,
    }


def verdict(result: dict[str, Any]) -> str:
    """What the measured shares mean for the target, in plain sentences.

    ``subproc_train_share``: ``train()``'s share of SubprocVecEnv's learn() wall
    time. ``ppo_floor_share``: the least time any contender spent outside
    ``env.step`` (train, policy inference, bookkeeping), as a share of the same:
    an env that took no time at all would still leave about that much."""
    share, floor = result["subproc_train_share"], result.get("ppo_floor_share")
    if share is None:
        return "SubprocVecEnv was not measured: no verdict on the target."
    if share > TARGET:
        return (
            f"train() alone is {share:.0%} of SubprocVecEnv's wall time, more than {TARGET:.0%}: "
            f"no env can meet the {TARGET:g}x target with these hyperparameters, "
            "since the same PPO's gradient updates take that long whatever the env."
        )
    text = (
        f"train() is {share:.0%} of SubprocVecEnv's wall time: the {TARGET:g}x target is reachable "
        f"only if rollouts and the rest ({1 - share:.0%} of it) shrink to {TARGET - share:.0%} of it or less."
    )
    if floor is not None and floor > TARGET:
        text += (
            f" PPO's own work outside env.step (train, policy inference, bookkeeping) took at least "
            f"{floor:.0%} of it for every contender: no env can meet the target on this machine, "
            "even one whose step cost nothing."
        )
    return text


def format_table(result: dict[str, Any]) -> str:
    m = result["machine"]
    loads = ", ".join(f"{x:.2f}" for x in result["load_avg_per_round"])
    lines = [
        f"{result['date']}; {m['cpus']} CPUs, {m['platform']}, Python {m['python']}; "
        f"SB3 {result['versions']['stable_baselines3']}, torch {result['versions']['torch']} "
        f"with {result['torch_threads']} threads (SB3's default, the same for every contender); "
        f"load average after each round: {loads}",
        f"PPO MlpPolicy, rl-zoo CartPole-v1 hyperparameters, {result['num_envs']} envs, "
        f"{result['steps']} timesteps x {result['rounds']} round(s), seed {result['seed']}",
        "",
        f"{'contender':14s} {'rnd':>3s} {'steps':>7s} {'setup s':>7s} {'learn s':>8s} {'rollout s':>9s} {'env.step s':>10s} "
        f"{'train s':>8s} {'other s':>8s} {'steps/s':>8s} {'CPU s':>7s} {'return':>7s}",
    ]
    for run in result["runs"]:
        ret = "-" if run["mean_return"] is None else f"{run['mean_return']:.1f}"
        lines.append(
            f"{run['contender']:14s} {run['round']:>3d} {run['timesteps']:>7d} {run['setup_s']:>7.1f} {run['total_s']:>8.1f} "
            f"{run['rollout_s']:>9.1f} {run['env_step_s']:>10.1f} {run['train_s']:>8.1f} {run['other_s']:>8.1f} "
            f"{run['rollout_steps_per_s']:>8.0f} {run['cpu_s']:>7.1f} {ret:>7s}"
        )
    lines += ["", f"{'ratio of medians (< 1: numerator faster)':44s} {'value':>6s} {'target':>12s}"]
    for r in result["ratios"]:
        target = "" if r["target"] is None else f"<={r['target']:g} {'met' if r['value'] <= r['target'] else 'MISSED'}"
        lines.append(f"{r['ratio']:44s} {r['value']:6.2f} {target:>12s}")
    lines += ["", verdict(result)]
    lines.append(
        "steps/s: env steps per second of rollout collection (env.step plus policy inference); "
        "learn s = rollout + train + other (logging, bookkeeping); setup s (launching the envs, building PPO) "
        "is not in it; return: mean episode return of SB3's last 100 episodes."
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    if args.sb3_steps < 1 or args.sb3_rounds < 1:
        raise SystemExit("--sb3-steps and --sb3-rounds must be >= 1")
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise SystemExit("the --sb3 benchmark needs Stable-Baselines3: pip install 'remoteenv[sb3]'") from None
    log = progress_log(args.json)
    result = measure(args.sb3_steps, args.sb3_rounds, args.sb3_seed, log=log)
    emit(result, args.json, format_table)
    return 0
