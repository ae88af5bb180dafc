"""The study's real-time check: its trained policies run in real time with a
think time, each episode is replayed in its exact twin
(:mod:`remoteenv.latency.twin`), and every episode is reported identical or
with the first step at which it differs.

Agent side. Which policies: the delay-unaware ones trained without delay
(``plain``, constant 0) and the ones trained with the actions in flight at
the smallest non-zero constant delay (``history``), one per seed. A policy
whose file is missing (a resumed study) is trained again first: lock-step
training repeats from its seed.

Returns are reported twice, on separate lines, and their scales differ: a
real-time step sums the rewards of every tick it lasted (a slow agent's
step spans several ticks), while the lock-step return (the same policy in
its training env, same seeds and step cap) counts one tick per step.

Runs in the agent process.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from remoteenv.latency.action_history import ActionHistory
from remoteenv.latency.study.design import Cell, StudyConfig
from remoteenv.latency.study.training import TrainedPolicy, evaluate, make_eval_env, policy_path, train

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


def lock_step_returns(config: StudyConfig, cell: Cell, policy: TrainedPolicy, episodes: int, seed: int) -> list[float]:
    """``policy``'s returns in its lock-step eval env, episode ``e`` from ``seed + e``, at most ``MAX_STEPS`` steps."""
    env = gym.wrappers.TimeLimit(make_eval_env(config, cell), MAX_STEPS)
    try:
        return evaluate(env, policy, episodes, seed)
    finally:
        env.close()


def run_twin_check(
    config: StudyConfig,
    policy_dir: str,
    episodes: int,
    think_ticks: tuple[float, float] = THINK_TICKS,
    max_steps: int = MAX_STEPS,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run each of :func:`checked_cells`' policies in real time, replay every
    episode in its exact twin and compare step by step; the map written to
    ``rt_replay.json``: per policy the comparison
    (:func:`~remoteenv.latency.twin.compare_real_time_and_replay`) and
    ``lock_step_returns``; ``identical``/``total``/``steps`` over all."""
    from remoteenv.latency.twin import compare_real_time_and_replay

    say = progress or (lambda _line: None)
    results = []
    for i, cell in enumerate(checked_cells(config)):
        policy = load_or_train(config, cell, policy_dir)
        k = cell.history_length
        wrap = (lambda env, k=k: ActionHistory(env, k)) if k else None
        seed = config.eval_seed + 1000 * i
        result = compare_real_time_and_replay(
            policy,
            config.env_id,
            config.env_kwargs,
            think_ticks=think_ticks,
            episodes=episodes,
            seed=seed,
            max_episode_steps=max_steps,
            wrap=wrap,
        )
        lock = lock_step_returns(config, cell, policy, episodes, seed)
        results.append(
            {
                **result,
                # after the comparison's own keys: its "seed" (the first episode's reset seed) is
                # kept as "episode_seed", and "seed" is the policy's training seed
                "episode_seed": result["seed"],
                "variant": cell.variant,
                "trained_delay": cell.delay,
                "seed": cell.seed,
                "lock_step_returns": lock,
            }
        )
        say(f"{cell.label()}: {result['identical']} of {result['total']} episodes identical in the exact twin")
        for e, row in enumerate(result["episodes"]):
            diff = row["first_difference"]
            say(f"  episode {e}: " + ("identical" if diff is None else f"first differs at step {diff['step']}"))
        say(f"  real-time returns: {_returns(result['real_time']['returns'])}")
        say(f"  lock-step returns: {_returns(lock)}")
        say(
            f"  (scales differ: a real-time step sums the ticks it lasted; lock-step counts one tick per step, {max_steps} at most)"
        )
    return {
        "think_ticks": list(think_ticks),
        "max_steps": max_steps,
        "episodes_per_policy": episodes,
        "policies": results,
        "identical": sum(r["identical"] for r in results),
        "total": sum(r["total"] for r in results),
        "steps": sum(r["steps"] for r in results),
    }


def _returns(values: list[float]) -> str:
    return ", ".join(f"{v:g}" for v in values)
