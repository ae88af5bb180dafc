"""Recording a real-time run for its twins (see :mod:`remoteenv.latency.twin`): the
substep at which each action took effect (the exact twin), the latencies (the
rounded trace twin), and a fingerprint of every observation.

Runs in the agent process.
"""

from __future__ import annotations

import math
import os
from typing import Any, SupportsFloat

import gymnasium as gym

from remoteenv.agent.launch.restart import INFO_RESTARTED
from remoteenv.latency.twin.digest import obs_digest
from remoteenv.latency.twin.episode import RecordedEpisode
from remoteenv.latency.twin.recorded_env import RecordedEnv
from remoteenv.latency.twin.recording_file import save_recording
from remoteenv.latency.twin.trace import ROUNDINGS, write_trace_file
from remoteenv.wire.run_options.real_time_modes import ELASTIC


class EpisodeLog:
    """The episodes of one world as they happen (the bookkeeping of
    :class:`LatencyRecorder` and of each world of :class:`LatencyRecorderVector
    <remoteenv.latency.twin.vector_recorder.LatencyRecorderVector>`).

    Attributes:
        episodes: the recorded episodes, oldest first (clear it at will).
        current: the episode in progress (None before the first reset and
            after an episode ended).
    """

    def __init__(self, rounding: str = "nearest", mode: str = ELASTIC, env: RecordedEnv | None = None) -> None:
        if rounding not in ROUNDINGS:
            raise ValueError(f"rounding must be one of {ROUNDINGS}, got {rounding!r}")
        self.rounding = rounding
        self.mode = mode
        #: The env every episode ran in (None: unknown).
        self.env = env
        self.episodes: list[RecordedEpisode] = []
        self.current: RecordedEpisode | None = None
        self._seed: int | None = None
        self._since_seed = 0
        self._tainted: str | None = None  # why resets since the last seeded one cannot be repeated

    def start(self, seed: int | None, obs: Any = None, info: dict[str, Any] | None = None, options: Any = None) -> None:
        """A reset, with its seed (None: unseeded), observation, info and
        options; an episode in progress is kept, cut short. A reset with
        options, or an unseeded one on a restarted sim, is named unreplayable."""
        if self.current is not None and self.current.steps:
            self.episodes.append(self.current)
        if seed is not None:
            self._seed, self._since_seed, self._tainted = int(seed), 0, None
        elif self.current is not None or self.episodes:
            self._since_seed += 1
        if (info or {}).get(INFO_RESTARTED) and seed is None:
            self._tainted = "an unseeded reset on a restarted sim (its scene RNG state was lost with the old process)"
        ep = RecordedEpisode(self._seed, self._since_seed, rounding=self.rounding, mode=self.mode, env=self.env)
        ep.unreplayable = self._tainted
        if options:
            ep.unreplayable = "a reset with options (the twin resets with the recorded seed only)"
        ep.obs_digests.append(obs_digest(obs))
        self.current = ep

    def record(
        self,
        ticks_elapsed: int,
        latency_ticks: float | None,
        reward: float,
        replay_substep: int | None = None,
        obs: Any = None,
        link_delay: float | None = None,
    ) -> None:
        """One real-time step (``latency_ticks`` None: its action never took
        effect; ``replay_substep``: see :attr:`RecordedEpisode.action_substeps`,
        None if the sim did not report it, which makes the episode unreplayable;
        ``link_delay``: its ``info["link_delay_s"]``, None without an emulated link)."""
        if self.current is None:
            raise RuntimeError("a real-time step outside an episode: call reset() first")
        ep = self.current
        ep.ticks_elapsed.append(int(ticks_elapsed))
        ep.latency_ticks.append(None if latency_ticks is None else float(latency_ticks))
        ep.rewards.append(float(reward))
        ep.obs_digests.append(obs_digest(obs))
        if link_delay is not None:
            if ep.link_delays is None:
                ep.link_delays = [0.0] * (ep.steps - 1)
            ep.link_delays.append(float(link_delay))
        if replay_substep is None:
            ep.unreplayable = ep.unreplayable or "the sim's replies carry no substep (a server without exact replay)"
        else:
            ep.action_substeps.append(int(replay_substep))

    def interrupt(self, why: str) -> None:
        """The episode in progress cannot be replayed (``why``) and ends here, cut short."""
        if self.current is not None:
            self.current.unreplayable = self.current.unreplayable or why
            self.episodes.append(self.current)
            self.current = None

    def record_info(self, info: dict[str, Any], reward: float, obs: Any) -> None:
        """One real-time step from its reply's ``info`` (see :meth:`record`)."""
        applied = info["action_sim_time"] is not None and info.get("latency_ticks") is not None
        applied = applied and math.isfinite(float(info["latency_ticks"]))
        substep = info.get("action_substep") if applied else info.get("substep")
        latency = float(info["latency_ticks"]) if applied else None
        link = info.get("link_delay_s")
        self.record(
            int(info["ticks_elapsed"]),
            latency,
            reward,
            None if substep is None else int(substep),
            obs,
            None if link is None else float(link),
        )

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


def real_time_mode(env: Any) -> str:
    """The regime an env's handshake names (elastic when it names none)."""
    handshake = getattr(getattr(env, "unwrapped", env), "handshake", None)
    return getattr(handshake, "real_time_mode", None) or ELASTIC


class LatencyRecorder(gym.Wrapper):
    """Records every real-time episode for its twins.

    Wrap a ``real_time=True`` env (outside its ``TimeLimit``: ``gym.make``'s
    env as it comes). Each step's ``info["action_substep"]`` (or
    ``info["substep"]`` for an action that never took effect),
    ``info["ticks_elapsed"]`` and ``info["latency_ticks"]``, its reward and a
    fingerprint of its observation are kept; an episode is complete when it
    terminates or is truncated, or is cut short by a reset. Nothing else
    changes: observations, rewards and infos pass through.

    What cannot be replayed is named in the episode
    (:attr:`RecordedEpisode.unreplayable`) and the exact twin refuses it: a
    step lost to a sim restart (``restart_on_failure``) or that raised, an
    unseeded reset on a restarted sim, a reset with options. Pauses and an
    emulated ``link_delay`` change only when actions arrive, which the
    substeps record: they replay exactly (and the link's delays, which the
    twin reports again). The env itself is recorded too (its arguments, time
    limit, real-time factor and link: :class:`~remoteenv.latency.twin.recorded_env.RecordedEnv`),
    so :func:`~remoteenv.latency_twin.make_twin` rebuilds it from the file.

    Args:
        env: the real-time env.
        rounding: how latencies become whole ticks in the traces
            (:data:`~remoteenv.latency.twin.ROUNDINGS`; see
            :func:`~remoteenv.latency.twin.twin_latency`).

    Attributes:
        log: the :class:`EpisodeLog`; ``episodes`` and ``current`` are its.
    """

    def __init__(self, env: gym.Env, rounding: str = "nearest") -> None:
        super().__init__(env)
        check_real_time(env, "LatencyRecorder")
        self.log = EpisodeLog(rounding, real_time_mode(env), RecordedEnv.from_env(env))

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
        self.log.start(seed, obs, info, options)
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if self.log.current is None:
            raise RuntimeError("LatencyRecorder.step outside an episode: call reset() first")
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except Exception as exc:
            self.log.interrupt(f"step {self.log.current.steps + 1} raised {type(exc).__name__}")
            raise
        if info.get(INFO_RESTARTED):
            self.log.interrupt(f"the sim was restarted at step {self.log.current.steps + 1}: the episode was lost")
            return obs, reward, terminated, truncated, info
        if "ticks_elapsed" not in info or "action_sim_time" not in info:
            raise ValueError("this env's step info has no ticks_elapsed/action_sim_time: is it real_time=True?")
        self.log.record_info(info, float(reward), obs)
        if terminated or truncated:
            self.log.finish(terminated, truncated)
        return obs, reward, terminated, truncated, info

    def save(self, path: str | os.PathLike[str], episode: int = -1) -> str:
        """Write recorded episode ``episode`` (default the last) as a recording
        file that :func:`~remoteenv.latency.twin.make_twin` replays exactly
        (:func:`~remoteenv.latency.twin.recording_file.save_recording`); return its path."""
        return save_recording(self.episodes[episode], path, self._env_id())

    def save_trace(self, path: str | os.PathLike[str], episode: int = -1) -> str:
        """Write recorded episode ``episode`` as a plain trace file for the
        rounded lock-step twin (``remoteenv.delays.Trace(path)`` loads it; see
        :func:`save_episode`); return its path."""
        return save_episode(self.episodes[episode], path, self._env_id())

    def _env_id(self) -> str:
        return getattr(self.env.spec, "id", None) or type(self.env.unwrapped).__name__


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
        "remoteenv lock-step twin of a real-time episode (remoteenv.latency.twin): one action delay",
        "per control tick; one line per real-time step: the countdown to the tick its action takes effect",
        f"{env_id}, {seed}: {rec.steps} steps, {rec.ticks} ticks, return {rec.episode_return:g}, {end}; "
        f"latencies in whole ticks: {rounding}",
    ]
    return write_trace_file(path, rec.values(rounding), header)


__all__ = ["EpisodeLog", "LatencyRecorder", "RecordedEpisode", "check_real_time", "real_time_mode", "save_episode"]
