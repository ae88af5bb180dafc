"""Real-time mode: physics paced to the wall clock while the agent thinks.

Runs in the sim process. :class:`RealTimeStepper` owns the schedule and
action handling of one world; :class:`RealTimeStepping` is the server loop's
strategy for all of them (see :mod:`remoteenv.sim.stepping`): the loop
answers requests between physics substeps and fires each world's substeps on
their deadlines. Both read time from an injected clock (``time.monotonic`` in
a sim process), in seconds.

Semantics:

- Physics substep ``n`` of an episode (``model.opt.timestep`` simulated
  seconds) runs at the wall-clock deadline ``t0 + n * timestep / factor``,
  where ``t0`` is the moment the reply to ``reset`` was sent. Deadlines are
  absolute, so waiting errors never add up to drift; a late process runs the
  missed substeps back to back to catch up.
- An action takes effect at the first substep boundary after it reaches the
  sim and is held until the next one replaces it; after a reset the scene's
  :meth:`~remoteenv.sim.base_env.BaseEnv.default_action` is held.
- Control ticks are ``frame_skip`` substeps, as in lock-step. The reply to a
  ``step`` is sent at the end of the first tick in which its action was in
  force; its reward is the sum over all ticks since the previous reply; its
  scene ``info`` is that of the last tick. When a tick terminates the
  episode, the world freezes there: nothing advances until the next reset,
  and a pending or later ``step`` is answered at once with ``terminated``.
- Before the first reset, and while frozen, nothing advances.

Emulated link: with ``link_delay`` (seconds: a number or a
:class:`~remoteenv.wire.delays.DelaySpec` with ``unit="s"``, e.g.
``Uniform(0.005, 0.015, unit="s")`` for jitter) every arriving action is
held back by a delay drawn for it, on top of the real one, before it can
take effect at the next substep: the extra round trip of a longer network,
put on the action's way in (its reply, sent once the action was in force,
is late by the same amount). Draws come from the link stream
(:data:`~remoteenv.wire.delay_line.LINK_STREAM`), seeded by
``reset(seed=...)`` (else by the launch seed, else OS entropy). A newer
request supersedes one still held back, so an older action never overrides
a newer one.

Pause: :meth:`RealTimeStepping.pause` stops every world's clock: no substep
runs, the held action stays, and on :meth:`RealTimeStepping.resume` every
deadline (and the arrival time of a request still waiting) shifts by the
paused wall time, so the pause counts in no pacing, arrival-to-application
or latency figure.

One clock per process: with several worlds (``--worlds K``) each world runs
its own episode on the same wall clock, its deadlines counted from its own
reset, each with its own held action.

Besides the scene's keys, every real-time step ``info`` carries (simulated
seconds unless noted):

``sim_time``          sim time of the returned observation.
``action_sim_time``   sim time the step's action took effect (None if the
                      episode terminated first).
``ticks_elapsed``     control ticks since the previous observation.
``latency_s``         ``action_sim_time`` minus the sim time of the
                      observation the agent last received (None if never
                      applied); ``latency_ticks`` the same in ticks.
``late``              True if at least one whole tick ran on the previous
                      action (``ticks_elapsed > 1``) or the action never took
                      effect.
``apply_delay_s``     wall seconds from the request's arrival at its world
                      (once decoded and checked) to the substep where it
                      took effect, the emulated link delay included.
``link_delay_s``      the emulated link delay drawn for this step's action
                      (wall seconds; 0.0 without ``link_delay``).
``pacing_overruns``   running count, for this world since the process
                      started, of substeps that ran more than one substep
                      period (``timestep / factor`` wall seconds) late.

The agent adds ``wall_round_trip_s`` (see :mod:`remoteenv.remote_env`).
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from remoteenv.sim.base_env import BaseEnv
from remoteenv.sim.channels import Channel, Outgoing
from remoteenv.sim.checks import RequestError
from remoteenv.wire.delay_line import LINK_STREAM, DelayStream
from remoteenv.wire.delays import SECONDS, DelaySpec, as_delay
from remoteenv.wire.errors import SCENE
from remoteenv.wire.protocol import error_reply
from remoteenv.wire.stats import RunningStats

#: A clock: seconds, monotonic (``time.monotonic`` in a sim process).
Clock = Callable[[], float]

_IDLE, _READY, _RUNNING, _FROZEN, _FAILED = "idle", "ready", "running", "frozen", "failed"


@dataclass
class _PendingStep:
    channel: Channel | None
    reply_to: Any
    seq: int
    action: Any
    arrived: float  # clock time when the request was handed over
    link_delay: float = 0.0  # emulated link: wall seconds it is held back after arriving
    applied_sim_time: float | None = None
    apply_delay_s: float | None = None


class RealTimeStepper:
    """One world advanced on the wall clock; driven by :class:`RealTimeStepping`.

    Args:
        env: the world.
        real_time_factor: simulated seconds per wall-clock second (> 0).
        clock: where wall time comes from (seconds, monotonic).
        link_delay: emulated extra link delay per action (wall seconds, a
            number or a spec in seconds); None or 0: none.
        seed: the world's launch seed: seeds the link stream at the first
            reset when that reset brings no seed (None: OS entropy).
    """

    def __init__(
        self,
        env: BaseEnv,
        real_time_factor: float = 1.0,
        clock: Clock = time.monotonic,
        link_delay: DelaySpec | float | None = None,
        seed: int | None = None,
    ) -> None:
        factor = float(real_time_factor)
        if not (math.isfinite(factor) and factor > 0):
            raise ValueError(f"real_time_factor must be a finite number > 0, got {real_time_factor!r}")
        self.env = env
        self.factor = factor
        self.clock = clock
        #: Wall seconds per physics substep.
        self.period = float(env.model.opt.timestep) / factor
        self.state = _IDLE
        #: Wall-clock lateness (s) of every substep boundary against its deadline;
        #: percentiles over the last 60 s of substeps (at most 200,000 of them).
        self.pacing_error = RunningStats(window=min(200_000, max(1000, int(60.0 / self.period))))
        #: Wall seconds from a step request's arrival to the substep where it took effect.
        self.apply_delay = RunningStats()
        #: Substeps run more than one ``period`` late, since the process started.
        self.overruns = 0
        self.substeps = 0
        self._t0 = 0.0
        self._n = 0
        self._held: Any = None
        self._pending: _PendingStep | None = None
        self._reward = 0.0
        self._ticks = 0
        self._obs: Any = None
        self._obs_time = 0.0
        self._info: dict[str, Any] = {}
        self._failure = ""
        link = as_delay(0.0 if link_delay is None else link_delay, SECONDS)
        #: The emulated link delay's draws (None: no emulated link).
        self.link: DelayStream | None = None if link.is_zero else DelayStream(link, LINK_STREAM)
        #: Emulated link delays drawn (wall seconds).
        self.link_delay = RunningStats()
        self._launch_seed = seed
        self._seeded = False
        self._paused_at: float | None = None

    # ------------------------------------------------------------ queries

    @property
    def has_reset(self) -> bool:
        return self.state != _IDLE

    @property
    def running(self) -> bool:
        return self.state == _RUNNING

    @property
    def awaiting_clock(self) -> bool:
        """Reset but the clock not yet started (its reply is not sent yet)."""
        return self.state == _READY

    @property
    def paused(self) -> bool:
        return self._paused_at is not None

    def next_deadline(self) -> float | None:
        """Clock time at which the next substep boundary is due (None: nothing runs)."""
        if self.state != _RUNNING or self._paused_at is not None:
            return None
        return self._t0 + self._n * self.period

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"mode": "real_time", "real_time_factor": self.factor, "action_delay": 0}
        if self.link is not None:
            out["link_delay_spec"] = self.link.spec.to_wire()
        return out

    def timing(self) -> dict[str, Any]:
        """Pacing figures of this world (wall seconds)."""
        return {
            "pacing_error_s": self.pacing_error.summary(),
            "apply_delay_s": self.apply_delay.summary(),
            "overruns": self.overruns,
            "substeps": self.substeps,
            "period_s": self.period,
            "link_delay_s": self.link_delay.summary(),
        }

    def clear_timing(self) -> None:
        self.pacing_error.clear()
        self.apply_delay.clear()
        self.link_delay.clear()
        self.overruns = 0
        self.substeps = 0

    # ------------------------------------------------------------ episode

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        """Synchronous reset; the clock starts with :meth:`start` once the reply is sent."""
        obs, info = self.env.reset(seed=seed, options=options)
        if self.link is not None:
            if seed is None and not self._seeded:
                seed = self._launch_seed
            if seed is not None:
                self.link.seed(seed)
                self._seeded = True
        self.state = _READY
        self._held = self.env.default_action()
        self._pending = None
        self._reward = 0.0
        self._ticks = 0
        self._obs = obs
        self._obs_time = float(self.env.data.time)
        self._info = {}
        self._n = 0
        return obs, info

    def start(self, now: float) -> None:
        """Start the clock: substep boundary 0 is due at ``now``."""
        if self.state == _READY:
            self._t0 = now
            self._n = 0
            self.state = _RUNNING
            if self._paused_at is not None:  # starts paused: its clock runs from the resume
                self._paused_at = now

    def pause(self, now: float) -> None:
        """Stop this world's clock at ``now`` (idempotent): no substep runs until :meth:`resume`."""
        if self._paused_at is None:
            self._paused_at = now

    def resume(self, now: float) -> float:
        """Restart the clock where it stopped; returns the paused wall seconds.

        Every deadline and a waiting request's arrival shift by the pause, so
        it counts in no timing figure."""
        if self._paused_at is None:
            return 0.0
        paused = max(0.0, now - self._paused_at)
        self._paused_at = None
        self._t0 += paused
        if self._pending is not None:
            self._pending.arrived += paused
        return paused

    def submit(self, seq: int, action: Any, channel: Channel | None, reply_to: Any) -> dict[str, Any] | None:
        """A checked ``step`` request; its arrival time is read from the clock now.

        Returns the reply at once when the world is frozen at a termination;
        otherwise None: the reply comes from :meth:`advance`. Raises
        :class:`RequestError` (kind ``scene``) while the world is stopped by
        a scene failure.
        """
        if self.state == _FAILED:
            raise RequestError(SCENE, self._failure)
        pending = _PendingStep(channel, reply_to, seq, action, self.clock())
        if self.state == _FROZEN:
            return self._reply(pending, terminated=True)
        if self.link is not None:
            pending.link_delay = float(self.link.draw())
            self.link_delay.add(pending.link_delay)
        # A newer request supersedes one still pending: its sender gave up on it.
        self._pending = pending
        return None

    def fail(self, exc: BaseException) -> list[Outgoing]:
        """The scene raised while advancing: stop this world until the next reset.

        Call it from the ``except`` block (the message carries the traceback).
        """
        self.state = _FAILED
        self._failure = (
            f"{type(exc).__name__} in the scene while advancing in real time: {exc}; "
            f"reset the env to continue\n{traceback.format_exc()}"
        )
        pending, self._pending = self._pending, None
        if pending is None:
            return []
        return [(pending.channel, pending.reply_to, error_reply(pending.seq, SCENE, self._failure))]

    def advance(self, now: float) -> list[Outgoing]:
        """Process the substep boundary that was due; ``now`` is the clock time it is processed.

        At a tick end the tick is scored (and may end the episode); then a
        newly arrived action takes effect, and the next substep is computed.
        """
        env = self.env
        deadline = self._t0 + self._n * self.period
        lateness = now - deadline
        self.pacing_error.add(lateness)
        if lateness > self.period:
            self.overruns += 1
        out: list[Outgoing] = []
        fs = env.frame_skip
        if self._n and self._n % fs == 0:
            obs, reward, terminated, info = env.post_step(self._held)
            self._obs, self._info = obs, info
            self._reward += float(reward)
            self._ticks += 1
            pending = self._pending
            if pending is not None and (pending.applied_sim_time is not None or terminated):
                self._pending = None
                reply = self._reply(pending, terminated=bool(terminated))
                out.append((pending.channel, pending.reply_to, reply))
            if terminated:
                self.state = _FROZEN
                return out
        pending = self._pending
        if pending is not None and pending.applied_sim_time is None and now >= pending.arrived + pending.link_delay:
            env.prepare_step(pending.action)
            self._held = pending.action
            pending.applied_sim_time = float(env.data.time)
            pending.apply_delay_s = self.clock() - pending.arrived
            self.apply_delay.add(pending.apply_delay_s)
        elif self._n % fs == 0:
            env.prepare_step(self._held)
        env.substep()
        self._n += 1
        self.substeps += 1
        return out

    def _reply(self, pending: _PendingStep, *, terminated: bool) -> dict[str, Any]:
        """The reply to ``pending``: the current observation and what accumulated since the last reply."""
        dt = self.env.dt
        sim_time = float(self.env.data.time)
        applied = pending.applied_sim_time
        latency = None if applied is None else applied - self._obs_time
        info = dict(self._info)
        info.update(
            sim_time=sim_time,
            action_sim_time=applied,
            ticks_elapsed=self._ticks,
            latency_s=latency,
            latency_ticks=None if latency is None else latency / dt,
            late=applied is None or self._ticks > 1,
            apply_delay_s=pending.apply_delay_s,
            link_delay_s=pending.link_delay,
            pacing_overruns=self.overruns,
        )
        reply = {
            "seq": pending.seq,
            "ok": True,
            "obs": self._obs,
            "reward": self._reward,
            "terminated": terminated,
            "truncated": False,
            "info": info,
        }
        self._reward = 0.0
        self._ticks = 0
        self._obs_time = sim_time
        return reply


class RealTimeStepping:
    """The loop strategy of a real-time server: one clock, each world on its own schedule.

    Args:
        envs: the worlds, one :class:`RealTimeStepper` each.
        real_time_factor: simulated seconds per wall-clock second (> 0).
        clock: where wall time comes from (seconds, monotonic).
        link_delay: emulated extra link delay per action (wall seconds; see
            :class:`RealTimeStepper`); each world draws from its own stream.
        seed: launch seed of world 0 (world ``w``: ``seed + w``) for the link streams.
    """

    def __init__(
        self,
        envs: Sequence[BaseEnv],
        real_time_factor: float = 1.0,
        clock: Clock = time.monotonic,
        link_delay: DelaySpec | float | None = None,
        seed: int | None = None,
    ) -> None:
        self.clock = clock
        self._worlds = [
            RealTimeStepper(
                env,
                real_time_factor=real_time_factor,
                clock=clock,
                link_delay=link_delay,
                seed=None if seed is None else seed + w,
            )
            for w, env in enumerate(envs)
        ]

    @property
    def worlds(self) -> list[RealTimeStepper]:
        return self._worlds

    @property
    def clock_waiting(self) -> bool:
        return any(w.awaiting_clock for w in self._worlds)

    def start_clocks(self, now: float) -> None:
        for w in self._worlds:
            w.start(now)

    def next_deadline(self) -> float | None:
        deadlines = [d for w in self._worlds if (d := w.next_deadline()) is not None]
        return min(deadlines) if deadlines else None

    def run_due(self, now: float) -> Iterator[Outgoing]:
        """Process one substep boundary of every world due at ``now``, earliest deadline first.

        A world whose scene raises is stopped (see :meth:`RealTimeStepper.fail`);
        the others go on.
        """
        due = sorted(
            (d, w) for w, world in enumerate(self._worlds) if (d := world.next_deadline()) is not None and d <= now
        )
        for _, w in due:
            world = self._worlds[w]
            try:
                out = world.advance(self.clock())
            except Exception as exc:  # the scene raised: keep serving
                out = world.fail(exc)
            yield from out

    def timing(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        """The ``timing`` command: every world's pacing figures; ``clear`` resets them after reading."""
        reply = {"worlds": [w.timing() for w in self._worlds]}
        if msg.get("clear"):
            for w in self._worlds:
                w.clear_timing()
        return reply

    def pause(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        """The ``pause`` command: stop every world's clock; ``sim_time`` per world (s)."""
        now = self.clock()
        for w in self._worlds:
            w.pause(now)
        return {"sim_time": [float(w.env.data.time) for w in self._worlds]}

    def resume(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        """The ``resume`` command: restart the clocks; ``sim_time`` per world (s, unchanged
        since the pause) and ``paused_s``, the wall seconds the clocks stood still
        (0.0 if they were not paused)."""
        now = self.clock()
        paused = [w.resume(now) for w in self._worlds]
        return {"sim_time": [float(w.env.data.time) for w in self._worlds], "paused_s": max(paused, default=0.0)}


__all__ = ["Clock", "RealTimeStepper", "RealTimeStepping"]
