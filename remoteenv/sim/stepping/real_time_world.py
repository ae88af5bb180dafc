"""One world on the wall clock: :class:`RealTimeStepper` (see :mod:`remoteenv.sim.stepping.real_time`).

Runs in the sim process. The semantics (deadlines, when actions take
effect and replies go, the emulated link, pause) and the info keys of a
real-time step are written down in :mod:`remoteenv.sim.stepping.real_time`, whose
:class:`~remoteenv.sim.stepping.real_time.RealTimeStepping` drives one of these per world.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.stepping.emulated_link import EmulatedLink
from remoteenv.sim.stepping.real_time_pacing import CATCH_UP_LIMIT_S, PacingFigures
from remoteenv.sim.stepping.real_time_replay import ReplayCursor, replay_from_options
from remoteenv.sim.stepping.real_time_reply import PendingStep, SinceReply
from remoteenv.sim.transport.channels import Channel, Outgoing
from remoteenv.sim.transport.checks import RequestError
from remoteenv.wire.messages.handshake import REAL_TIME
from remoteenv.wire.protocol import error_reply
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import FIXED_STEP
from remoteenv.wire.wire_errors import PROTOCOL, SCENE

#: A clock: seconds, monotonic (``time.monotonic`` in a sim process).
Clock = Callable[[], float]
#: The options of a real-time world that asks for nothing else (factor 1, elastic, no emulated link).
REAL_TIME_OPTIONS = RunOptions(real_time=True)

_IDLE, _READY, _RUNNING, _FROZEN, _FAILED = "idle", "ready", "running", "frozen", "failed"


class RealTimeStepper(PacingFigures):
    """One world advanced on the wall clock; driven by :class:`RealTimeStepping`.
    Its pacing figures (:class:`~remoteenv.sim.stepping.real_time_pacing.PacingFigures`)
    are kept as it goes.

    Args:
        env: the world.
        run: its real-time options: ``real_time_factor`` (simulated seconds
            per wall-clock second), ``real_time_mode`` (the regime,
            :mod:`remoteenv.wire.run_options.real_time_modes`) and
            ``link_delay`` (the emulated link's extra delay per action, wall
            seconds; None or 0: none).
        clock: where wall time comes from (seconds, monotonic).
        seed: the world's launch seed: seeds the link stream at the first
            reset when that reset brings no seed (None: OS entropy).
    """

    def __init__(
        self,
        env: BaseEnv,
        run: RunOptions = REAL_TIME_OPTIONS,
        clock: Clock = time.monotonic,
        seed: int | None = None,
    ) -> None:
        if not run.real_time:
            raise ValueError("a real-time world's run options need real_time=True")
        self.mode = run.real_time_mode
        factor = float(run.real_time_factor)
        self.env = env
        self.factor = factor
        self.clock = clock
        self._link = EmulatedLink(run.link_delay, seed)
        #: The emulated link delay's draws (None: no emulated link).
        self.link = self._link.stream
        super().__init__(float(env.model.opt.timestep) / factor, self._link.delays)
        self.state = _IDLE
        self._t0 = 0.0
        self._n = 0
        self._held: Any = None
        self._pending: PendingStep | None = None
        self._since = SinceReply()
        self._failure = ""
        self._paused_at: float | None = None
        self._replay: ReplayCursor | None = None

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
        if self.state != _RUNNING or self._paused_at is not None or self._replay is not None:
            return None
        return self._t0 + self._n * self.period

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"mode": REAL_TIME, "real_time_factor": self.factor, "action_delay": 0}
        out["real_time_mode"] = self.mode
        self._link.describe(out)
        return out

    # ------------------------------------------------------------ episode

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        """Synchronous reset; the clock starts with :meth:`start` once the reply is sent.

        Options carrying a replay schedule put the world into replay for this
        episode (:mod:`remoteenv.sim.stepping.real_time_replay`)."""
        options, replay = replay_from_options(options, self.mode, self.env.frame_skip, self.link is not None)
        obs, info = self.env.reset(seed=seed, options=options)
        self._replay = replay
        self._link.reset(seed)
        self.state = _READY
        self._held = self.env.default_action()
        self._pending = None
        self._since.start(obs, float(self.env.data.time))
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

        Every deadline and a waiting request's arrival (one that came during
        the pause: its start) shift by the pause, so it counts in no timing figure."""
        if self._paused_at is None:
            return 0.0
        stopped, self._paused_at = self._paused_at, None
        paused = max(0.0, now - stopped)
        self._t0 += paused
        if self._pending is not None:  # one that came during the pause arrived, on the clock, at its start
            self._pending.arrived = min(self._pending.arrived, stopped) + paused
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
        pending = PendingStep(channel, reply_to, seq, action, self.clock())
        if self.state == _FROZEN:
            return self._reply(pending, terminated=True)
        if self._replay is not None:
            return self._replay_step(pending)
        pending.link_delay = self._link.draw()
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

        At a tick end the tick is scored (and may end the episode); then an
        action read by the boundary's deadline takes effect, and the next
        substep is computed. A boundary over ``CATCH_UP_LIMIT_S`` late slips the clock first.
        """
        lateness = now - (self._t0 + self._n * self.period)
        self.record_lateness(lateness)
        if lateness > CATCH_UP_LIMIT_S:  # too far behind to catch up: this boundary is due now
            self._t0 += lateness
            self.record_slip(lateness)
        return self._boundary(now)

    def _replay_step(self, pending: PendingStep) -> dict[str, Any]:
        """Replay: run boundaries until ``pending``'s reply, its action arriving
        just before the substep the schedule names."""
        assert self._replay is not None
        if self.state != _RUNNING:
            raise RequestError(PROTOCOL, "a replayed step before its reset's reply: reset first")
        pending.apply_at = self._replay.next_substep(self._n)
        pending.link_delay = self._replay.link_delay
        self._pending = pending
        while True:
            try:
                out = self._boundary(None)
            except Exception as exc:  # the scene raised: stop as on the clock
                self.fail(exc)
                raise RequestError(SCENE, self._failure) from None
            if out:
                return out[0][2]

    def _boundary(self, now: float | None) -> list[Outgoing]:
        """Process substep boundary ``self._n`` at clock time ``now`` (None: replay,
        where the pending action arrives at its scheduled substep)."""
        env = self.env
        out: list[Outgoing] = []
        fs = env.frame_skip
        if self._n and self._n % fs == 0:
            # Replay renders a tick's cameras only when a reply carries its observation.
            obs, reward, terminated, info = env.finish_tick(self._held, observe=now is not None)
            if now is None and (terminated or self._replies_here(self._pending)):
                obs = env.observe(obs)
            self._since.add_tick(obs, reward, info)
            pending = self._pending
            if pending is not None and (pending.applied_sim_time is not None or terminated):
                self._pending = None
                reply = self._reply(pending, terminated=bool(terminated))
                out.append((pending.channel, pending.reply_to, reply))
            if terminated:
                self.state = _FROZEN
                return out
        pending = self._pending
        if pending is not None and pending.applied_sim_time is None and self._arrived(pending, replay=now is None):
            env.prepare_step(pending.action)
            self._held = pending.action
            pending.applied_sim_time = float(env.data.time)
            pending.applied_substep = self._n
            if now is not None:
                pending.apply_delay_s = self.clock() - pending.arrived
                self.apply_delay.add(pending.apply_delay_s)
            if self.mode == FIXED_STEP:  # the step ends at the boundary where its action takes effect
                self._pending = None
                out.append((pending.channel, pending.reply_to, self._reply(pending, terminated=False)))
        elif self._n % fs == 0:
            env.prepare_step(self._held)
        env.substep()
        self._n += 1
        self.substeps += 1
        return out

    def _replies_here(self, pending: PendingStep | None) -> bool:
        """Replay, at a tick end: whether ``pending``'s reply goes at this boundary
        (its action in force; fixed-step: its action takes effect here)."""
        if pending is None:
            return False
        return pending.applied_sim_time is not None or (self.mode == FIXED_STEP and self._arrived(pending, replay=True))

    def _arrived(self, pending: PendingStep, *, replay: bool) -> bool:
        """Whether ``pending``'s action may take effect at boundary ``self._n``
        (fixed-step: only at a tick boundary after the episode's first tick).
        On the clock the boundary's *deadline* counts, not when it is processed:
        one processed late whose deadline preceded the action's reading (plus
        the link's delay) keeps the action in force then (see the module docs)."""
        if self.mode == FIXED_STEP and (self._n == 0 or self._n % self.env.frame_skip):
            return False
        if replay:
            return self._n >= pending.apply_at
        return self._t0 + self._n * self.period >= pending.arrived + pending.link_delay

    def _reply(self, pending: PendingStep, *, terminated: bool) -> dict[str, Any]:
        """The reply to ``pending``: the current observation and what accumulated since the last reply."""
        return self._since.reply(
            pending,
            terminated=terminated,
            sim_time=float(self.env.data.time),
            substep=self._n,
            frame_skip=self.env.frame_skip,
            overruns=self.overruns,
            link=self.link is not None,
        )


__all__ = ["Clock", "RealTimeStepper"]
