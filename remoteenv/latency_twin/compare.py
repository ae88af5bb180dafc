"""Running a policy in real time and in its lock-step twin, and comparing the returns.

See :mod:`remoteenv.latency_twin` for what the twin reproduces and
``docs/latency-twin.md`` for the comparison's tolerance and why.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from remoteenv.latency_twin.recorder import LatencyRecorder, RecordedEpisode, save_episode
from remoteenv.latency_twin.replay import make_twin
from remoteenv.latency_twin.trace import twin_latency

#: A policy: observation in, action out. A ``reset()`` method, if it has one,
#: is called at each episode's start (for policies that remember, e.g. their last action).
Policy = Callable[[Any], Any]
#: Wraps the env a policy sees (e.g. ``lambda env: ActionHistory(env, 4)``), the same way in both runs.
Wrap = Callable[[gym.Env], gym.Env]

#: Default equivalence margin: the mean paired return difference must lie
#: within this fraction of the real-time mean return (docs/latency-twin.md says why).
DEFAULT_RELATIVE_TOLERANCE = 0.10


def _reset_policy(policy: Policy) -> None:
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()


def _play(
    env: gym.Env, policy: Policy, seed: int, resets_after_seed: int = 0, think: Callable[[], None] | None = None
) -> dict[str, Any]:
    """One episode from ``reset(seed=seed)`` (then ``resets_after_seed``
    unseeded resets), ``think()`` before each step: ``{"return", "steps", "terminated"}``."""
    obs, _ = env.reset(seed=seed)
    for _ in range(resets_after_seed):
        obs, _ = env.reset()
    _reset_policy(policy)
    total, steps, terminated, truncated = 0.0, 0, False, False
    while not (terminated or truncated):
        action = policy(obs)
        if think is not None:
            think()
        obs, reward, terminated, truncated, _ = env.step(action)
        total += float(reward)
        steps += 1
    return {"return": total, "steps": steps, "terminated": bool(terminated)}


def run_real_time(
    policy: Policy,
    env_id: str,
    env_kwargs: dict[str, Any] | None = None,
    *,
    think_ticks: tuple[float, float] = (0.0, 3.0),
    episodes: int = 10,
    seed: int = 0,
    real_time_factor: float = 1.0,
    max_episode_steps: int | None = None,
    wrap: Wrap | None = None,
    rounding: str = "nearest",
) -> list[RecordedEpisode]:
    """``episodes`` real-time episodes of ``policy``, episode ``e`` from
    ``reset(seed=seed + e)``, recorded by a :class:`LatencyRecorder`.

    Before each action the agent sleeps a think time drawn uniformly from
    ``think_ticks`` control ticks of wall time (a tick is ``dt /
    real_time_factor`` wall seconds), from ``numpy.random.default_rng(seed)``;
    the sim runs on meanwhile. ``max_episode_steps`` caps the real-time
    steps (decisions) per episode (None: the env's registered limit).
    ``rounding``: the recorded episodes' default (see :class:`LatencyRecorder`)."""
    limit: dict[str, Any] = {} if max_episode_steps is None else {"max_episode_steps": max_episode_steps}
    env = LatencyRecorder(
        gym.make(env_id, real_time=True, real_time_factor=real_time_factor, **limit, **(env_kwargs or {})),
        rounding,
    )
    outer = wrap(env) if wrap else env
    rng = np.random.default_rng(seed)
    tick_s = float(env.unwrapped.dt) / real_time_factor  # type: ignore[attr-defined]
    low, high = think_ticks

    def think() -> None:
        time.sleep(rng.uniform(low, high) * tick_s)

    try:
        for e in range(episodes):
            _play(outer, policy, seed + e, think=think)
    finally:
        outer.close()
    return env.episodes


def replay_episode(
    policy: Policy,
    env_id: str,
    episode: RecordedEpisode,
    env_kwargs: dict[str, Any] | None = None,
    *,
    max_episode_steps: int | None = None,
    wrap: Wrap | None = None,
    rounding: str | None = None,
) -> dict[str, Any]:
    """Replay ``episode`` in its lock-step twin with ``policy``; the twin's
    ``{"return", "steps", "terminated", "ticks"}``. ``max_episode_steps``:
    the real-time run's limit in steps (None: the registered one);
    ``rounding``: of the trace (None: the episode's). Refuses an episode
    recorded without a seed (its start state cannot be reproduced)."""
    if episode.seed is None:
        raise ValueError("this episode's reset had no seed: reset real-time runs with a seed to replay them")
    twin = make_twin(env_id, episode.trace(rounding), max_episode_steps, **(env_kwargs or {}))
    outer = wrap(twin) if wrap else twin
    try:
        result = _play(outer, policy, episode.seed, episode.resets_after_seed)
    finally:
        outer.close()
    return {**result, "ticks": twin.ticks}


def compare_returns(
    real_time: Sequence[float],
    replay: Sequence[float],
    *,
    relative_tolerance: float = DEFAULT_RELATIVE_TOLERANCE,
    confidence: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> dict[str, Any]:
    """Compare paired returns (episode ``e`` of both runs shares its reset
    seed and its latencies): an equivalence test of the means, and the
    distance between the two distributions.

    The percentile-bootstrap ``confidence`` interval of the mean paired
    difference ``replay - real_time`` (``resamples`` resamples of the
    episodes, from ``default_rng(seed)``) decides the ``verdict``:
    ``"equivalent"`` when it lies within ``+-tolerance``, where
    ``tolerance = relative_tolerance * mean(|real_time|)``; ``"different"``
    when it excludes 0; else ``"inconclusive"`` (too few episodes for the
    spread: run more). ``match`` is ``verdict == "equivalent"``. Also
    reported: how many pairs are equal, the largest difference, and the
    two-sample Kolmogorov-Smirnov distance of the two return distributions
    (with its p-value when scipy is installed; remoteenv does not need it)."""
    a = np.asarray(real_time, dtype=np.float64)
    b = np.asarray(replay, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1 or a.size < 2:
        raise ValueError(f"need two equal-length lists of >= 2 paired returns, got {a.shape} and {b.shape}")
    diff = b - a
    rng = np.random.default_rng(seed)
    means = diff[rng.integers(0, diff.size, size=(resamples, diff.size))].mean(axis=1)
    tail = (1.0 - confidence) / 2.0
    low, high = (float(q) for q in np.quantile(means, [tail, 1.0 - tail]))
    tolerance = relative_tolerance * float(np.abs(a).mean())
    if -tolerance <= low and high <= tolerance:
        verdict = "equivalent"
    elif low > 0 or high < 0:
        verdict = "different"
    else:
        verdict = "inconclusive"
    try:
        from scipy.stats import ks_2samp  # optional: remoteenv does not depend on scipy

        ks_pvalue: float | None = float(ks_2samp(a, b).pvalue)
    except ImportError:
        ks_pvalue = None
    return {
        "episodes": int(a.size),
        "real_time_mean": float(a.mean()),
        "replay_mean": float(b.mean()),
        "mean_difference": float(diff.mean()),
        "ci": [low, high],
        "confidence": confidence,
        "tolerance": tolerance,
        "relative_tolerance": relative_tolerance,
        "equal_pairs": int((diff == 0).sum()),
        "max_abs_difference": float(np.abs(diff).max()),
        "ks_distance": ks_distance(a, b),
        "ks_pvalue": ks_pvalue,
        "verdict": verdict,
        "match": verdict == "equivalent",
    }


def ks_distance(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """The two-sample Kolmogorov-Smirnov distance: the largest gap between the
    empirical distribution functions of ``a`` and ``b`` (0: the same sample
    distribution, 1: no overlap)."""
    x, y = np.sort(np.asarray(a, dtype=np.float64)), np.sort(np.asarray(b, dtype=np.float64))
    grid = np.union1d(x, y)
    return float(np.abs(np.searchsorted(x, grid, "right") / x.size - np.searchsorted(y, grid, "right") / y.size).max())


def compare_recorded(
    policy: Policy,
    env_id: str,
    recorded: Sequence[RecordedEpisode],
    env_kwargs: dict[str, Any] | None = None,
    *,
    max_episode_steps: int | None = None,
    wrap: Wrap | None = None,
    rounding: str = "nearest",
    relative_tolerance: float = DEFAULT_RELATIVE_TOLERANCE,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Replay every recorded episode in its twin (:func:`replay_episode`) and
    compare with the real-time run (:func:`compare_returns`); a JSON-able
    dict: ``rounding``, ``real_time`` and ``replay`` (per-episode
    ``returns``, ``steps``, ``ticks``, ``terminated``), ``endings`` (pairs
    that ended alike), ``traces`` (per-episode summaries, latency figures in
    ticks) and ``comparison``. Call it twice on one recording to compare
    roundings."""
    say = progress or (lambda _line: None)
    replays = []
    for e, ep in enumerate(recorded):
        r = replay_episode(
            policy, env_id, ep, env_kwargs, max_episode_steps=max_episode_steps, wrap=wrap, rounding=rounding
        )
        replays.append(r)
        say(f"replay {e} ({rounding}): return {r['return']:g}, real time {ep.episode_return:g}")
    summaries = [ep.summary(rounding) for ep in recorded]
    real = [v for ep in recorded for v in ep.latency_ticks if v is not None]
    twin = [
        twin_latency(t, v, rounding)
        for ep in recorded
        for t, v in zip(ep.ticks_elapsed, ep.latency_ticks)
        if v is not None
    ]
    return {
        "rounding": rounding,
        "real_time": {
            "returns": [ep.episode_return for ep in recorded],
            "steps": [ep.steps for ep in recorded],
            "ticks": [ep.ticks for ep in recorded],
            "terminated": [ep.terminated for ep in recorded],
        },
        "replay": {key: [r[name] for r in replays] for key, name in _REPLAY_KEYS},
        "endings": {
            "same_termination": sum(ep.terminated == r["terminated"] for ep, r in zip(recorded, replays)),
            "same_ticks": sum(ep.ticks == r["ticks"] for ep, r in zip(recorded, replays)),
            "replay_beyond_recording": sum(r["ticks"] > ep.ticks for ep, r in zip(recorded, replays)),
        },
        "traces": {
            "episodes": summaries,
            "values": int(sum(ep.ticks for ep in recorded)),
            "mean_latency_ticks": float(np.mean(real)) if real else None,
            "mean_twin_latency_ticks": float(np.mean(twin)) if twin else None,
            "max_twin_latency_ticks": int(max(twin)) if twin else None,
            "mean_twin_shift_ticks": float(np.mean(np.subtract(twin, real))) if real else None,
        },
        "comparison": compare_returns(
            [ep.episode_return for ep in recorded],
            [r["return"] for r in replays],
            relative_tolerance=relative_tolerance,
        ),
    }


_REPLAY_KEYS = (("returns", "return"), ("steps", "steps"), ("ticks", "ticks"), ("terminated", "terminated"))


def compare_real_time_and_replay(
    policy: Policy,
    env_id: str = "remoteenv/CartPole-v0",
    env_kwargs: dict[str, Any] | None = None,
    *,
    think_ticks: tuple[float, float] = (0.0, 3.0),
    episodes: int = 10,
    seed: int = 0,
    real_time_factor: float = 1.0,
    max_episode_steps: int | None = None,
    wrap: Wrap | None = None,
    rounding: str = "nearest",
    trace_dir: str | os.PathLike[str] | None = None,
    relative_tolerance: float = DEFAULT_RELATIVE_TOLERANCE,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run ``policy`` in real time (:func:`run_real_time`), then replay and
    compare (:func:`compare_recorded`). ``trace_dir``: also save each
    episode's trace there as ``episode-<e>.trace.txt``. ``progress`` gets a
    line per episode.

    Returns :func:`compare_recorded`'s dict plus the configuration,
    ``trace_files``, ``wall_s`` (both runs) and the load average before and after."""
    load_before = os.getloadavg()
    started = time.monotonic()
    recorded = run_real_time(
        policy,
        env_id,
        env_kwargs,
        think_ticks=think_ticks,
        episodes=episodes,
        seed=seed,
        real_time_factor=real_time_factor,
        max_episode_steps=max_episode_steps,
        wrap=wrap,
        rounding=rounding,
    )
    if progress is not None:
        progress(f"real time: returns {[ep.episode_return for ep in recorded]}")
    files = []
    if trace_dir is not None:
        os.makedirs(trace_dir, exist_ok=True)
        for e, ep in enumerate(recorded):
            files.append(save_episode(ep, os.path.join(os.fspath(trace_dir), f"episode-{e}.trace.txt"), env_id))
    result = compare_recorded(
        policy,
        env_id,
        recorded,
        env_kwargs,
        max_episode_steps=max_episode_steps,
        wrap=wrap,
        rounding=rounding,
        relative_tolerance=relative_tolerance,
        progress=progress,
    )
    return {
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs or {}),
        "think_ticks": list(think_ticks),
        "episodes": episodes,
        "seed": seed,
        "real_time_factor": real_time_factor,
        "max_episode_steps": max_episode_steps,
        **result,
        "trace_files": files,
        "wall_s": time.monotonic() - started,
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
    }


__all__ = [
    "compare_real_time_and_replay",
    "compare_recorded",
    "compare_returns",
    "ks_distance",
    "replay_episode",
    "run_real_time",
]
