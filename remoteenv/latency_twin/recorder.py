"""Recording a real-time run's latencies as its twin's traces (see :mod:`remoteenv.latency_twin`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from remoteenv.latency_twin.trace import ROUNDINGS, twin_latency, twin_values, write_trace_file
from remoteenv.wire.delays.delays import Trace


@dataclass
class RecordedEpisode:
    """One real-time episode, as its twin needs it and as it went.

    Attributes:
        seed: the seed of this episode's reset, or of the last seeded reset
            before it (None: never seeded).
        resets_after_seed: unseeded resets from that seeded reset up to and
            including this episode's (0 when this episode's reset had the
            seed). The twin repeats them to reach the same scene RNG state
            (the scene must draw from its RNG only when it resets, as the
            shipped scenes do).
        ticks_elapsed: each step's ``info["ticks_elapsed"]``.
        latency_ticks: each step's ``info["latency_ticks"]`` (None when the
            action never took effect).
        rewards: each step's reward (summed over its ticks by the sim).
        terminated, truncated: how the episode ended (both False if a reset
            cut it short).
        rounding: the default of :meth:`values` and :meth:`trace`.
    """

    seed: int | None
    resets_after_seed: int
    ticks_elapsed: list[int] = field(default_factory=list)
    latency_ticks: list[float | None] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    terminated: bool = False
    truncated: bool = False
    rounding: str = "nearest"

    @property
    def steps(self) -> int:
        """Real-time steps (decisions) of the episode."""
        return len(self.ticks_elapsed)

    @property
    def ticks(self) -> int:
        """Control ticks the episode ran: the length of its trace."""
        return int(sum(self.ticks_elapsed))

    @property
    def episode_return(self) -> float:
        return float(sum(self.rewards))

    def values(self, rounding: str | None = None) -> list[int]:
        """The twin's trace values (:func:`~remoteenv.latency_twin.twin_values`)."""
        return twin_values(self.ticks_elapsed, self.latency_ticks, rounding or self.rounding)

    def trace(self, rounding: str | None = None) -> Trace:
        """The twin's action delay: ``Trace(values)`` in ticks."""
        return Trace(self.values(rounding))

    def summary(self, rounding: str | None = None) -> dict[str, Any]:
        """Plain figures of the episode (JSON-able); latencies in ticks."""
        rounding = rounding or self.rounding
        pairs = [(t, v) for t, v in zip(self.ticks_elapsed, self.latency_ticks) if v is not None]
        real = np.array([v for _, v in pairs], dtype=np.float64)
        twin = np.array([twin_latency(t, v, rounding) for t, v in pairs], dtype=np.float64)
        return {
            "seed": self.seed,
            "resets_after_seed": self.resets_after_seed,
            "steps": self.steps,
            "ticks": self.ticks,
            "return": self.episode_return,
            "terminated": self.terminated,
            "truncated": self.truncated,
            "late_steps": int(sum(t > 1 for t in self.ticks_elapsed)),
            "unapplied_steps": int(sum(v is None for v in self.latency_ticks)),
            "mean_latency_ticks": float(real.mean()) if real.size else None,
            "max_latency_ticks": float(real.max()) if real.size else None,
            "rounding": rounding,
            "mean_twin_latency_ticks": float(twin.mean()) if twin.size else None,
            # How much later (positive) or earlier the twin applies each action, on average.
            "mean_twin_shift_ticks": float((twin - real).mean()) if real.size else None,
        }


class EpisodeLog:
    """The episodes of one world as they happen (the bookkeeping of
    :class:`LatencyRecorder` and of each world of :class:`LatencyRecorderVector
    <remoteenv.latency_twin.vector_recorder.LatencyRecorderVector>`).

    Attributes:
        episodes: the recorded episodes, oldest first (clear it at will).
        current: the episode in progress (None before the first reset and
            after an episode ended).
    """

    def __init__(self, rounding: str = "nearest") -> None:
        if rounding not in ROUNDINGS:
            raise ValueError(f"rounding must be one of {ROUNDINGS}, got {rounding!r}")
        self.rounding = rounding
        self.episodes: list[RecordedEpisode] = []
        self.current: RecordedEpisode | None = None
        self._seed: int | None = None
        self._since_seed = 0

    def start(self, seed: int | None) -> None:
        """A reset, with its seed (None: unseeded); an episode in progress is kept, cut short."""
        if self.current is not None and self.current.steps:
            self.episodes.append(self.current)
        if seed is not None:
            self._seed, self._since_seed = int(seed), 0
        elif self.current is not None or self.episodes:
            self._since_seed += 1
        self.current = RecordedEpisode(self._seed, self._since_seed, rounding=self.rounding)

    def record(self, ticks_elapsed: int, latency_ticks: float | None, reward: float) -> None:
        """One real-time step (``latency_ticks`` None: its action never took effect)."""
        if self.current is None:
            raise RuntimeError("a real-time step outside an episode: call reset() first")
        self.current.ticks_elapsed.append(int(ticks_elapsed))
        self.current.latency_ticks.append(None if latency_ticks is None else float(latency_ticks))
        self.current.rewards.append(float(reward))

    def finish(self, terminated: bool, truncated: bool) -> None:
        """The episode in progress ended."""
        if self.current is not None:
            self.current.terminated, self.current.truncated = bool(terminated), bool(truncated)
            self.episodes.append(self.current)
            self.current = None


def check_real_time(env: Any, who: str) -> None:
    """Refuse an env whose handshake says lock-step."""
    handshake = getattr(getattr(env, "unwrapped", env), "handshake", None)
    if handshake is not None and not handshake.real_time:
        raise ValueError(f"{who} records the latencies of a real-time run: make the env with real_time=True")


class LatencyRecorder(gym.Wrapper):
    """Records every real-time episode for its lock-step twin.

    Wrap a ``real_time=True`` env (outside its ``TimeLimit``: ``gym.make``'s
    env as it comes). Each step's ``info["ticks_elapsed"]``,
    ``info["latency_ticks"]`` and ``info["action_sim_time"]`` are kept; an
    episode is complete when it terminates or is truncated, or is cut short
    by a reset. Nothing else changes: observations, rewards and infos pass
    through.

    Args:
        env: the real-time env.
        rounding: how latencies become whole ticks in the traces
            (:data:`~remoteenv.latency_twin.ROUNDINGS`; see
            :func:`~remoteenv.latency_twin.twin_latency`).

    Attributes:
        log: the :class:`EpisodeLog`; ``episodes`` and ``current`` are its.
    """

    def __init__(self, env: gym.Env, rounding: str = "nearest") -> None:
        super().__init__(env)
        check_real_time(env, "LatencyRecorder")
        self.log = EpisodeLog(rounding)

    @property
    def episodes(self) -> list[RecordedEpisode]:
        """The recorded episodes, oldest first."""
        return self.log.episodes

    @property
    def current(self) -> RecordedEpisode | None:
        """The episode in progress, if any."""
        return self.log.current

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.log.start(seed)
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if self.log.current is None:
            raise RuntimeError("LatencyRecorder.step outside an episode: call reset() first")
        obs, reward, terminated, truncated, info = self.env.step(action)
        if "ticks_elapsed" not in info or "action_sim_time" not in info:
            raise ValueError("this env's step info has no ticks_elapsed/action_sim_time: is it real_time=True?")
        applied = info["action_sim_time"] is not None and info.get("latency_ticks") is not None
        self.log.record(info["ticks_elapsed"], info["latency_ticks"] if applied else None, float(reward))
        if terminated or truncated:
            self.log.finish(terminated, truncated)
        return obs, reward, terminated, truncated, info

    def save(self, path: str | os.PathLike[str], episode: int = -1) -> str:
        """Write recorded episode ``episode`` (default the last) as a trace file
        that ``remoteenv.delays.Trace(path)`` loads (see :func:`save_episode`); return its path."""
        env_id = getattr(self.env.spec, "id", None) or type(self.env.unwrapped).__name__
        return save_episode(self.episodes[episode], path, env_id)


def save_episode(
    episode: RecordedEpisode, path: str | os.PathLike[str], env_id: str, rounding: str | None = None
) -> str:
    """Write ``episode``'s twin trace to ``path``: a text file with a commented
    header (``env_id``, seed, steps, ticks, return, how it ended, rounding),
    then one line per real-time step (its countdown). Returns the path."""
    rec = episode
    rounding = rounding or rec.rounding
    end = "terminated" if rec.terminated else "truncated" if rec.truncated else "cut short by a reset"
    seed = "no seed" if rec.seed is None else f"reset seed {rec.seed}"
    if rec.resets_after_seed:
        seed += f" and {rec.resets_after_seed} unseeded reset(s)"
    header = [
        "remoteenv lock-step twin of a real-time episode (remoteenv.latency_twin): one action delay",
        "per control tick; one line per real-time step: the countdown to the tick its action takes effect",
        f"{env_id}, {seed}: {rec.steps} steps, {rec.ticks} ticks, return {rec.episode_return:g}, {end}; "
        f"latencies in whole ticks: {rounding}",
    ]
    return write_trace_file(path, rec.values(rounding), header)


__all__ = ["EpisodeLog", "LatencyRecorder", "RecordedEpisode", "check_real_time", "save_episode"]
