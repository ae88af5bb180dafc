"""Running a policy in real time and in its exact twin, and comparing them step by step.

See :mod:`remoteenv.latency.twin` for what the twin reproduces and
``docs/latency-twin.md`` for how exactness is checked.

Runs in the agent process.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from remoteenv.latency.twin.digest import obs_digest
from remoteenv.latency.twin.exact_twin import ExactTwin
from remoteenv.latency.twin.recorder import LatencyRecorder, RecordedEpisode
from remoteenv.latency.twin.recording_file import save_recording
from remoteenv.latency.twin.replay import make_twin
from remoteenv.latency.twin.return_stats import DEFAULT_RELATIVE_TOLERANCE, compare_returns, ks_distance
from remoteenv.wire.run_options.real_time_modes import ELASTIC

#: A policy: observation in, action out. A ``reset()`` method, if it has one,
#: is called at each episode's start (for policies that remember, e.g. their last action).
Policy = Callable[[Any], Any]
#: Wraps the env a policy sees (e.g. ``lambda env: ActionHistory(env, 4)``), the same way in both runs.
Wrap = Callable[[gym.Env], gym.Env]


def _reset_policy(policy: Policy) -> None:
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()


def _play(
    env: gym.Env,
    policy: Policy,
    seed: int,
    resets_after_seed: int = 0,
    think: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """One episode from ``reset(seed=seed)`` (then ``resets_after_seed``
    unseeded resets), ``think()`` before each step: ``{"return", "steps",
    "terminated", "truncated", "rewards", "obs_digests"}`` (the digests of
    the observations the env returned, the reset's first)."""
    obs, _ = env.reset(seed=seed)
    for _ in range(resets_after_seed):
        obs, _ = env.reset()
    _reset_policy(policy)
    digests, rewards = [obs_digest(obs)], []
    terminated = truncated = False
    while not (terminated or truncated):
        action = policy(obs)
        if think is not None:
            think()
        obs, reward, terminated, truncated, _ = env.step(action)
        rewards.append(float(reward))
        digests.append(obs_digest(obs))
    return {
        "return": float(sum(rewards)),
        "steps": len(rewards),
        "terminated": bool(terminated),
        "truncated": bool(truncated),
        "rewards": rewards,
        "obs_digests": digests,
    }


def run_real_time(
    policy: Policy,
    env_id: str,
    env_kwargs: dict[str, Any] | None = None,
    *,
    think_ticks: tuple[float, float] = (0.0, 3.0),
    episodes: int = 10,
    seed: int = 0,
    real_time_factor: float = 1.0,
    real_time_mode: str = ELASTIC,
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
    ``rounding``: the recorded episodes' default for the rounded trace twin."""
    limit: dict[str, Any] = {} if max_episode_steps is None else {"max_episode_steps": max_episode_steps}
    env = LatencyRecorder(
        gym.make(
            env_id,
            real_time=True,
            real_time_factor=real_time_factor,
            real_time_mode=real_time_mode,
            **limit,
            **(env_kwargs or {}),
        ),
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
) -> dict[str, Any]:
    """Play ``episode``'s exact twin (:func:`make_twin`) closed loop with
    ``policy`` from the recorded start: :func:`_play`'s dict, with the
    twin's own ``obs_digests``, ``rewards`` and flags (taken below ``wrap``,
    where the recorder took the real run's). Refuses an episode that cannot
    be replayed (:attr:`RecordedEpisode.unreplayable`, no seed)."""
    twin = make_twin(env_id, episode, max_episode_steps, **(env_kwargs or {}))
    assert isinstance(twin, ExactTwin)
    outer = wrap(twin) if wrap else twin
    try:
        assert episode.seed is not None  # make_twin refused it otherwise
        played = _play(outer, policy, episode.seed, episode.resets_after_seed)
    finally:
        outer.close()
    return {
        **played,
        "return": float(sum(twin.rewards)),
        "steps": len(twin.rewards),
        "rewards": twin.rewards,
        "obs_digests": twin.obs_digests,
        "terminated": twin.terminated,
        "truncated": twin.truncated,
    }


def first_difference(episode: RecordedEpisode, replay: dict[str, Any]) -> dict[str, Any] | None:
    """Where ``replay`` (:func:`replay_episode`'s dict) first departs from
    the recorded ``episode``: None when every observation (bit for bit),
    reward (exactly), the ending flags and the step count agree; else
    ``{"step", "differs"}``, ``step`` counted from 1 (0: the reset's
    observation) and ``differs`` naming what: ``"obs"``, ``"reward"``,
    ``"terminated"``, ``"truncated"``, ``"steps"`` (one run ended there)."""
    real, twin = episode.obs_digests, replay["obs_digests"]
    for j in range(max(len(real), len(twin))):
        if j >= len(real) or j >= len(twin):
            return {"step": j, "differs": ["steps"]}
        differs = []
        if real[j] != twin[j]:
            differs.append("obs")
        if j and episode.rewards[j - 1] != replay["rewards"][j - 1]:
            differs.append("reward")
        last = j == len(real) - 1
        if last and j == len(twin) - 1:
            if episode.terminated != replay["terminated"]:
                differs.append("terminated")
            if episode.truncated != replay["truncated"]:
                differs.append("truncated")
        if differs:
            return {"step": j, "differs": differs}
    return None


def compare_recorded(
    policy: Policy,
    env_id: str,
    recorded: Sequence[RecordedEpisode],
    env_kwargs: dict[str, Any] | None = None,
    *,
    max_episode_steps: int | None = None,
    wrap: Wrap | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Replay every recorded episode in its exact twin and compare it step by
    step (:func:`first_difference`); a JSON-able dict: ``episodes`` (per
    episode ``identical``, ``first_difference``, ``steps``, ``ticks``,
    ``real_time_return``, ``replay_return``, ``replay_steps``),
    ``identical`` (how many), ``total``, ``steps`` (real-time steps
    compared, summed), ``ticks`` (control ticks they lasted), ``real_time``
    and ``replay`` (per-episode ``returns``, ``steps``, ``terminated``).
    A real-time return sums, per step, the rewards of the ticks the step
    lasted: compare it with the replay's, not with a lock-step run's."""
    say = progress or (lambda _line: None)
    rows, replays = [], []
    for e, ep in enumerate(recorded):
        r = replay_episode(policy, env_id, ep, env_kwargs, max_episode_steps=max_episode_steps, wrap=wrap)
        replays.append(r)
        diff = first_difference(ep, r)
        rows.append(
            {
                "identical": diff is None,
                "first_difference": diff,
                "steps": ep.steps,
                "ticks": ep.ticks,
                "real_time_return": ep.episode_return,
                "replay_return": r["return"],
                "replay_steps": r["steps"],
            }
        )
        state = "identical" if diff is None else f"differs first at step {diff['step']} ({', '.join(diff['differs'])})"
        say(f"episode {e}: {ep.steps} steps, {ep.ticks} ticks, return {ep.episode_return:g}: {state}")
    return {
        "episodes": rows,
        "identical": sum(row["identical"] for row in rows),
        "total": len(rows),
        "steps": sum(ep.steps for ep in recorded),
        "ticks": sum(ep.ticks for ep in recorded),
        "real_time": {
            "returns": [ep.episode_return for ep in recorded],
            "steps": [ep.steps for ep in recorded],
            "terminated": [ep.terminated for ep in recorded],
        },
        "replay": {
            "returns": [r["return"] for r in replays],
            "steps": [r["steps"] for r in replays],
            "terminated": [r["terminated"] for r in replays],
        },
    }


def compare_real_time_and_replay(
    policy: Policy,
    env_id: str = "remoteenv/CartPole-v0",
    env_kwargs: dict[str, Any] | None = None,
    *,
    think_ticks: tuple[float, float] = (0.0, 3.0),
    episodes: int = 10,
    seed: int = 0,
    real_time_factor: float = 1.0,
    real_time_mode: str = ELASTIC,
    max_episode_steps: int | None = None,
    wrap: Wrap | None = None,
    recording_dir: str | os.PathLike[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run ``policy`` in real time (:func:`run_real_time`), then replay each
    episode in its exact twin and compare (:func:`compare_recorded`).
    ``recording_dir``: also save each episode's recording there as
    ``episode-<e>.json`` (:meth:`LatencyRecorder.save`'s format), and replay
    from those files. ``progress`` gets a line per episode.

    Returns :func:`compare_recorded`'s dict plus the configuration,
    ``recording_files``, ``wall_s`` (both runs) and the load average before and after."""
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
        real_time_mode=real_time_mode,
        max_episode_steps=max_episode_steps,
        wrap=wrap,
    )
    files = []
    if recording_dir is not None:
        from remoteenv.latency.twin.recording_file import load_recording

        os.makedirs(recording_dir, exist_ok=True)
        for e, ep in enumerate(recorded):
            files.append(save_recording(ep, os.path.join(os.fspath(recording_dir), f"episode-{e}.json"), env_id))
        recorded = [load_recording(path)[0] for path in files]
    result = compare_recorded(
        policy, env_id, recorded, env_kwargs, max_episode_steps=max_episode_steps, wrap=wrap, progress=progress
    )
    return {
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs or {}),
        "think_ticks": list(think_ticks),
        "episodes_run": episodes,
        "seed": seed,
        "real_time_factor": real_time_factor,
        "real_time_mode": real_time_mode,
        "max_episode_steps": max_episode_steps,
        **result,
        "recording_files": files,
        "wall_s": time.monotonic() - started,
        "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
    }


__all__ = [
    "DEFAULT_RELATIVE_TOLERANCE",
    "compare_real_time_and_replay",
    "compare_recorded",
    "compare_returns",
    "first_difference",
    "ks_distance",
    "replay_episode",
    "run_real_time",
]
