"""The study's real-time check: its trained policies run in real time with a
think time, and in lock-step replaying the latencies each action had
(:mod:`remoteenv.latency_twin`); the two return distributions are compared.

Agent side. Which policies: the delay-unaware ones trained without delay
(``plain``, constant 0) and the ones trained with the actions in flight at
the smallest non-zero constant delay (``history``), one per seed. A policy
whose file is missing (a resumed study) is trained again first: lock-step
training repeats from its seed.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from remoteenv.latency_study.design import Cell, StudyConfig
from remoteenv.latency_study.training import TrainedPolicy, policy_path, train
from remoteenv.wrappers import ActionHistory

#: Think time before each real-time action: uniform in this range, in control ticks.
THINK_TICKS = (0.0, 3.0)
#: Real-time episodes are cut after this many (elastic) steps.
MAX_STEPS = 200


def checked_cells(config: StudyConfig) -> list[Cell]:
    """The cells whose policies the check runs (see the module docs)."""
    out = []
    if 0 in config.delays:
        out += [Cell("plain", "constant", 0, seed) for seed in config.seeds]
    nonzero = sorted(d for d in config.delays if d > 0)
    if nonzero:
        out += [Cell("history", "constant", nonzero[0], seed) for seed in config.seeds]
    return out


def load_or_train(config: StudyConfig, cell: Cell, policy_dir: str) -> TrainedPolicy:
    path = policy_path(policy_dir, cell)
    if not os.path.exists(path + ".zip"):
        policy, _ = train(config, cell)
        policy.save(path)
    return TrainedPolicy.load(path)


def run_twin_check(
    config: StudyConfig,
    policy_dir: str,
    episodes: int,
    think_ticks: tuple[float, float] = THINK_TICKS,
    max_steps: int = MAX_STEPS,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Compare real time and its lock-step replay for each of :func:`checked_cells`'
    policies; the map written to ``rt_replay.json``."""
    from remoteenv.latency_twin import compare_real_time_and_replay, compare_returns

    results = []
    for i, cell in enumerate(checked_cells(config)):
        policy = load_or_train(config, cell, policy_dir)
        k = cell.history_length
        wrap = (lambda env, k=k: ActionHistory(env, k)) if k else None
        result = compare_real_time_and_replay(
            policy,
            config.env_id,
            config.env_kwargs,
            think_ticks=think_ticks,
            episodes=episodes,
            seed=config.eval_seed + 1000 * i,
            max_episode_steps=max_steps,
            wrap=wrap,
        )
        results.append({"variant": cell.variant, "trained_delay": cell.delay, "seed": cell.seed, **result})
        if progress is not None:
            c = result["comparison"]
            progress(
                f"{cell.label()}: real time {c['real_time_mean']:.1f}, replay {c['replay_mean']:.1f}, {c['verdict']}"
            )
    pairs = [(a, b) for r in results for a, b in zip(r["real_time"]["returns"], r["replay"]["returns"])]
    return {
        "pooled": compare_returns([a for a, _ in pairs], [b for _, b in pairs]) if len(pairs) >= 2 else None,
        "think_ticks": list(think_ticks),
        "max_steps": max_steps,
        "episodes_per_policy": episodes,
        "policies": results,
        "all_equivalent": all(r["comparison"]["verdict"] == "equivalent" for r in results),
    }
