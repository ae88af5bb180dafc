"""``python -m remoteenv bench --startup``: from ``gym.make`` to the first ``reset``, and a restart.

Agent side; it launches agent processes that launch sims. Each repeat starts
one fresh agent process per way of starting sims, in alternating order:
forked by a zygote (the default, :mod:`remoteenv.agent.launch.zygote`) and the
plain way (``REMOTEENV_ZYGOTE=0``: ``python <scene script>``). Every agent
imports Gymnasium and remoteenv first (not timed), then times:

- ``first make``: ``gym.make(id)`` → first ``reset`` returned, the first env
  of the process (with a zygote: the zygote's start and imports included);
- ``later make``: the same for ``--startup-later`` more envs made one after
  another in that process (each closed before the next);
- ``restart``: the sim of an env made with ``restart_on_failure=True`` is
  killed (SIGKILL), then the next ``step`` (which relaunches it) and the
  ``reset`` after it;
- ``vector``: ``gym.make_vec(id, N, envs_per_process=1)`` → first ``reset``:
  N sim processes at once (``--startup-vector N``, 0 to skip);
- ``default vector`` and ``later default vector``: ``gym.make_vec(id, M)``
  in the default layout → first ``reset`` (``--startup-default-vector M``, 0
  to skip), twice: the first measures what a world costs (through a probe
  of one world when the scene's source sets ``stacked_hooks = True``, else
  in its first launch, which may then be relaunched in another layout), the
  later starts in the layout the first learnt
  (:mod:`remoteenv.agent.vector.layout_memory`).

Wall seconds (median and min over repeats) and CPU seconds of the agent and
every process below it. With ``--hog`` a second pass runs with that many
CPU hogs beside it. It measures and prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import textwrap
import time
from typing import Any

from remoteenv.benchmarks.harness.anchors import CpuHog
from remoteenv.benchmarks.harness.report import emit, progress_log

#: The ways of starting sims compared, with the environment each agent runs in.
MODES = {"zygote": {"REMOTEENV_ZYGOTE": "1"}, "plain": {"REMOTEENV_ZYGOTE": "0"}}
ROWS = ("first make", "later make", "restart", "vector", "default vector", "later default vector")
TARGET_S = 0.3

#: One agent process: times its envs and prints one JSON line.
AGENT = textwrap.dedent(
    """
    import json, os, signal, sys, time
    import gymnasium as gym
    import remoteenv
    from remoteenv.agent.launch.sim_process import kill_group
    from remoteenv.benchmarks.harness.anchors import cpu_seconds
    from remoteenv.benchmarks.startup_time import ROWS

    env_id, later, vector, default = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    out = {row: [] for row in ROWS}

    def timed(row, work):
        cpu, wall = cpu_seconds(), time.perf_counter()
        value = work()
        out[row].append([time.perf_counter() - wall, cpu_seconds() - cpu])
        return value

    def make_and_reset(**kwargs):
        env = gym.make(env_id, **kwargs)
        env.reset(seed=0)
        return env

    timed("first make", make_and_reset).close()
    for _ in range(later):
        timed("later make", make_and_reset).close()
    env = make_and_reset(restart_on_failure=True)
    pid = env.unwrapped.pid
    kill_group(pid, signal.SIGKILL)
    while env.unwrapped.launcher.sims[0].death() is None:
        time.sleep(0.001)

    def relaunch():
        info = env.step(env.action_space.sample())[-1]
        assert info.get("remoteenv_restarted"), info
        env.reset(seed=0)

    timed("restart", relaunch)
    out["zygote"] = env.unwrapped.launcher.sims[0].zygote_pid is not None
    env.close()

    def make_vector():
        envs = gym.make_vec(env_id, num_envs=vector, vectorization_mode="vector_entry_point", envs_per_process=1)
        envs.reset(seed=0)
        return envs

    if vector:
        timed("vector", make_vector).close()

    def make_default():
        envs = gym.make_vec(env_id, num_envs=default, vectorization_mode="vector_entry_point")
        envs.reset(seed=0)
        return envs

    if default:
        timed("default vector", make_default).close()
        timed("later default vector", make_default).close()
    print(json.dumps(out))
    """
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("start-up benchmark (--startup)")
    g.add_argument("--startup-id", default="remoteenv/CartPole-v0", help="the env id to make (default CartPole)")
    g.add_argument("--startup-repeats", type=int, default=7, help="fresh agent processes per mode (default 7)")
    g.add_argument("--startup-later", type=int, default=3, help="later makes per agent process (default 3)")
    g.add_argument("--startup-vector", type=int, default=8, help="sims of the vector row (default 8; 0: no row)")
    g.add_argument(
        "--startup-default-vector",
        type=int,
        default=16,
        help="worlds of the default-layout rows (default 16; 0: no rows)",
    )
    g.add_argument("--startup-json", default=None, metavar="PATH", help="also write the result as JSON ('-': stdout)")
    try:  # shared with --batched, which defines it when present
        g.add_argument(
            "--hog", type=int, nargs="?", const=1, default=0, help="run this many CPU hogs beside it (default 1)"
        )
    except argparse.ArgumentError:
        pass


def run_agent(env_id: str, mode: str, later: int, vector: int, default: int = 0) -> dict[str, Any]:
    """One fresh agent process in ``mode``; its timings."""
    env = {**os.environ, **MODES[mode]}
    argv = [sys.executable, "-c", AGENT, env_id, str(later), str(vector), str(default)]
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"the {mode} agent failed ({done.returncode}):\n{done.stderr[-2000:]}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    if result.pop("zygote") != (mode == "zygote"):
        raise RuntimeError(f"the {mode} agent's sims were not started the {mode} way")
    return result


def measure(env_id: str, repeats: int, later: int, vector: int, log: Any, default: int = 0) -> dict[str, Any]:
    """``{mode: {row: {"wall": [...], "cpu": [...]}}}`` over ``repeats`` alternating rounds."""
    samples: dict[str, dict[str, dict[str, list[float]]]] = {
        mode: {row: {"wall": [], "cpu": []} for row in ROWS} for mode in MODES
    }
    for r in range(repeats):
        order = list(MODES) if r % 2 == 0 else list(reversed(MODES))
        for mode in order:
            for row, pairs in run_agent(env_id, mode, later, vector, default).items():
                for wall, cpu in pairs:
                    samples[mode][row]["wall"].append(wall)
                    samples[mode][row]["cpu"].append(cpu)
        log(f"round {r + 1}/{repeats} done (load {os.getloadavg()[0]:.2f})")
    return samples


def summary(samples: dict[str, Any]) -> dict[str, Any]:
    return {
        mode: {
            row: {
                "median_s": statistics.median(v["wall"]),
                "min_s": min(v["wall"]),
                "cpu_median_s": statistics.median(v["cpu"]),
                "n": len(v["wall"]),
            }
            for row, v in rows.items()
            if v["wall"]
        }
        for mode, rows in samples.items()
    }


def format_table(result: dict[str, Any]) -> str:
    lines = [f"{result['env_id']}: gym.make -> first reset, and a restart (wall s, median / min; CPU s, median)"]
    for name, passes in result["passes"].items():
        lines.append(f"\n{name} (load average {passes['load_before']:.2f} before, {passes['load_after']:.2f} after)")
        lines.append(f"{'':24s} | {'zygote':^26s} | {'plain':^26s}")
        for row in ROWS:
            if row not in passes["summary"]["zygote"]:
                continue
            cells = []
            for mode in MODES:
                c = passes["summary"][mode][row]
                cells.append(f"{c['median_s']:.3f} / {c['min_s']:.3f}  cpu {c['cpu_median_s']:.3f}")
            label = row
            if row == "vector":
                label = f"vector, {result['vector']}"
            elif "default vector" in row:
                label = f"{row}, {result.get('default_vector')}"
            lines.append(f"{label:24s} | {cells[0]:^26s} | {cells[1]:^26s}")
    lines.append(f"\ntarget: gym.make -> first reset <= {TARGET_S} s on a quiet host; {os.cpu_count()} CPUs")
    lines.append(f"{time.strftime('%Y-%m-%d %H:%M %Z')}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    log = progress_log(args.startup_json)
    passes: dict[str, Any] = {}
    hogs = [0] + ([args.hog] if getattr(args, "hog", 0) else [])
    for hog in hogs:
        name = "quiet" if hog == 0 else f"beside {hog} CPU hog(s)"
        log(f"# {name}")
        load_before = os.getloadavg()[0]
        with CpuHog(hog):
            samples = measure(
                args.startup_id,
                args.startup_repeats,
                args.startup_later,
                args.startup_vector,
                log,
                args.startup_default_vector,
            )
        passes[name] = {
            "load_before": load_before,
            "load_after": os.getloadavg()[0],
            "summary": summary(samples),
            "samples": samples,
        }
    result = {
        "env_id": args.startup_id,
        "vector": args.startup_vector,
        "default_vector": args.startup_default_vector,
        "passes": passes,
    }
    emit(result, args.startup_json, format_table)
    return 0


__all__ = ["add_arguments", "run"]
