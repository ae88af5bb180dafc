"""Making a recorded real-time episode's twin: the exact one, or the rounded lock-step one
(see :mod:`remoteenv.latency.twin`).

Runs in the agent process.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium as gym

from remoteenv.latency.twin.episode import RecordedEpisode
from remoteenv.latency.twin.exact_twin import ExactTwin, check_replayable
from remoteenv.latency.twin.recording_file import is_recording, load_recording
from remoteenv.latency.twin.trace import decision_ticks
from remoteenv.wire.delays.delay_specs import Trace
from remoteenv.wire.messages.handshake import LOCK_STEP


class LockStepTwin(gym.Wrapper):
    """The lock-step twin of one recorded real-time episode: each ``step`` is
    one elastic step of the recording.

    ``env`` must be a lock-step env launched with ``action_delay=trace`` and
    no time limit of its own (:func:`make_twin` makes both). ``step(action)``
    sends ``action`` once per lock-step tick for as many ticks as the
    recorded step spanned (its countdown in the trace,
    :func:`~remoteenv.latency.twin.decision_ticks`), stopping early when the
    episode ends, and returns as a real-time reply does: the observation at
    the end of the last tick, the reward summed over the ticks, that tick's
    ``terminated`` and ``info``, with ``ticks_elapsed`` (ticks run),
    ``latency_ticks`` (the twin's whole-tick latency of this step, the
    countdown's first value, reported only once the action is in force by the
    reply, as real time reports it: None when it is not), ``latency_s``
    and ``late`` (more than one tick, or the action not in force by the
    reply). The infos of the ticks of the last step are kept in
    :attr:`last_ticks`.

    Beyond the recorded episode's end the trace wraps around (as every
    :class:`~remoteenv.delays.Trace` does): a twin that outlasts its
    real-time episode goes on with the latencies of the episode's start, and
    ``info["twin_beyond_recording"]`` is True from then on. ``max_steps``
    truncates an episode after that many steps (decisions), as the real-time
    run's time limit did; None: no limit.

    Resets: the sim rewinds the trace at every seeded reset; an unseeded
    reset continues it, so one is accepted only before any step since the
    last seeded reset (as :attr:`RecordedEpisode.resets_after_seed
    <remoteenv.latency.twin.RecordedEpisode.resets_after_seed>` needs).
    """

    def __init__(self, env: gym.Env, trace: Trace, max_steps: int | None = None) -> None:
        super().__init__(env)
        self.trace = trace
        self.holds = decision_ticks(trace.values)
        self.max_steps = max_steps
        handshake = getattr(env.unwrapped, "handshake", None)
        if handshake is not None:
            stepping = handshake["stepping"]
            expected = None if trace.is_zero else trace.to_wire()
            if stepping.get("mode") != LOCK_STEP or stepping.get("action_delay_spec") != expected:
                raise ValueError(
                    "LockStepTwin needs a lock-step env launched with action_delay=<this trace> and no "
                    "observation delay; make it with remoteenv.latency.twin.make_twin"
                )
        #: The infos of the lock-step ticks of the last ``step``, in order.
        self.last_ticks: list[dict[str, Any]] = []
        self._draws = 0  # ticks since the trace was last rewound: the next value's index
        self._decision = 0  # the next countdown's index in holds
        self._steps = 0

    @property
    def ticks(self) -> int:
        """Lock-step ticks run since the last seeded reset (the trace's position)."""
        return self._draws

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if seed is None and self._draws:
            raise ValueError(
                "the twin replays its trace from a seeded reset: pass the recorded episode's seed "
                "(an unseeded reset after steps would continue the trace in the sim)"
            )
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._draws = self._decision = 0
        self._steps = 0
        self.last_ticks = []
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        first = int(self.trace.values[self._draws % len(self.trace.values)])
        hold = self.holds[self._decision % len(self.holds)]
        self._decision += 1
        total = 0.0
        self.last_ticks = []
        for _ in range(hold):
            obs, reward, terminated, truncated, info = self.env.step(action)
            self._draws += 1
            self.last_ticks.append(info)
            total += float(reward)
            if terminated or truncated:
                break
        self._steps += 1
        ticks = len(self.last_ticks)
        landed = first < ticks  # a latency is known once the action took effect, never before
        info = dict(info)
        info.update(
            ticks_elapsed=ticks,
            latency_ticks=first if landed else None,
            latency_s=first * float(getattr(self.env.unwrapped, "dt", 0.0)) if landed else None,
            late=ticks > 1 or not landed,
            twin_beyond_recording=self._draws > len(self.trace.values),
        )
        if self.max_steps is not None and self._steps >= self.max_steps and not terminated:
            truncated = True
        return obs, total, terminated, truncated, info


def make_twin(
    env_id: str,
    trace: RecordedEpisode | Trace | Sequence[int] | str | os.PathLike[str],
    max_episode_steps: int | None = None,
    **kwargs: Any,
) -> ExactTwin | LockStepTwin:
    """The twin of one recorded real-time episode.

    ``trace`` a :class:`~remoteenv.latency.twin.RecordedEpisode` or the path of
    a recording file (as :meth:`LatencyRecorder.save
    <remoteenv.latency.twin.LatencyRecorder.save>` writes it): the exact twin,
    ``ExactTwin(gym.make(env_id, real_time=True,
    real_time_mode=<the recording's>, max_episode_steps=...), episode)``; it
    refuses an episode that cannot be replayed, saying why. A recording that
    knows its env (:attr:`RecordedEpisode.env
    <remoteenv.latency_twin.RecordedEpisode.env>`, every recording this
    version writes) is rebuilt from it: its arguments, time limit,
    ``real_time_factor`` and ``link_delay``; an explicit argument (or
    ``max_episode_steps``) that contradicts it is refused in one line, and
    only where and how the sim runs (transport, timeouts, restarts) may be
    added.

    A :class:`~remoteenv.delays.Trace`, its values, or a plain trace file's
    path (:meth:`LatencyRecorder.save_trace
    <remoteenv.latency.twin.LatencyRecorder.save_trace>`): the rounded
    lock-step twin, ``LockStepTwin(gym.make(env_id, action_delay=trace, ...),
    trace, max_episode_steps)``; the lock-step env itself gets no time limit
    (its steps are ticks).

    ``max_episode_steps``: the twin's limit in steps (decisions), as the
    real-time run counted them; None: the recording's, else the env id's
    registered limit. ``kwargs`` go to ``gym.make`` (e.g. the scene's own,
    like ``continuous=True``, for a recording that does not know its env).
    """
    what = "the recorded episode"
    if isinstance(trace, (str, os.PathLike)):
        what = f"recording {os.fspath(trace)}"
        if not os.path.exists(trace):
            raise FileNotFoundError(f"make_twin: {os.fspath(trace)} does not exist (a recording or trace file)")
        if is_recording(trace):
            trace, _ = load_recording(trace)
    if isinstance(trace, RecordedEpisode):
        check_replayable(trace)  # before a sim starts
        env = gym.make(env_id, **exact_twin_kwargs(trace, max_episode_steps, kwargs, what))
        try:
            return ExactTwin(env, trace)
        except BaseException:
            env.close()
            raise
    spec = trace if isinstance(trace, Trace) else Trace(trace)
    if max_episode_steps is None:
        max_episode_steps = gym.spec(env_id).max_episode_steps
    env = gym.make(env_id, action_delay=spec, max_episode_steps=-1, **kwargs)  # -1: no TimeLimit
    return LockStepTwin(env, spec, max_episode_steps)


def exact_twin_kwargs(
    episode: RecordedEpisode, max_episode_steps: int | None, explicit: dict[str, Any], what: str
) -> dict[str, Any]:
    """The ``gym.make`` arguments of ``episode``'s exact twin: its recorded env
    (if known) with the ``explicit`` ones, which may not contradict it."""
    explicit = dict(explicit)
    mode = explicit.pop("real_time_mode", episode.mode)
    if mode != episode.mode:
        raise ValueError(f"make_twin: real_time_mode={mode!r} contradicts {what} ({episode.mode!r}): drop it")
    if explicit.pop("real_time", True) is not True:
        raise ValueError(f"make_twin: the exact twin of {what} runs with real_time=True: drop real_time")
    out: dict[str, Any] = {"real_time": True, "real_time_mode": episode.mode}
    recorded = episode.env
    if recorded is None:
        out.update(explicit)
        if max_episode_steps is not None:
            out["max_episode_steps"] = max_episode_steps
        return out
    if recorded.unrecorded and not set(recorded.unrecorded) <= set(explicit):
        missing = sorted(set(recorded.unrecorded) - set(explicit))
        raise ValueError(f"make_twin: {what} could not keep {', '.join(missing)}: pass them to make_twin")
    limit = recorded.max_episode_steps
    if max_episode_steps is not None and limit is not None and max_episode_steps != limit:
        raise ValueError(f"make_twin: max_episode_steps={max_episode_steps} contradicts {what} ({limit}): drop it")
    recorded.check_explicit(explicit, what)
    out.update(recorded.make_kwargs())
    out.update(explicit)
    limit = max_episode_steps if max_episode_steps is not None else limit
    out["max_episode_steps"] = -1 if limit is None else limit  # -1: no TimeLimit, as recorded
    return out


__all__ = ["LockStepTwin", "exact_twin_kwargs", "make_twin"]
