"""Real-time mode: physics paced to the wall clock while the agent thinks.

Runs in the sim process. :class:`RealTimeStepper` owns the schedule and
action handling of one world; :func:`serve_real_time` is the server loop that
answers requests between physics substeps and fires each world's substeps on
their deadlines.

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
``apply_delay_s``     wall seconds from the request's arrival in the sim
                      process to the substep where it took effect.
``pacing_overruns``   running count, for this world since the process
                      started, of substeps that ran more than one substep
                      period (``timestep / factor`` wall seconds) late.

The agent adds ``wall_round_trip_s`` (see :mod:`remoteenv.remote_env`).
"""

from __future__ import annotations

import math
import select
import time
import traceback
from dataclasses import dataclass
from typing import Any


from remoteenv.wire import protocol
from remoteenv.wire.stats import RunningStats
from remoteenv.sim.base_env import BaseEnv

_PARENT_CHECK_S = 0.25
#: Wall seconds before a deadline at which waiting turns from sleeping to spinning.
_SPIN_S = 0.0003

#: A reply waiting to be sent: (whom to answer, reply map with "seq"); whom to
#: answer is opaque to the stepper (the server loop's channel and reply_to).
Outgoing = tuple[Any, dict[str, Any]]

_IDLE, _READY, _RUNNING, _FROZEN, _FAILED = "idle", "ready", "running", "frozen", "failed"


@dataclass
class _PendingStep:
    identity: Any
    seq: int
    action: Any
    arrived: float  # time.monotonic() when the request was read
    applied_sim_time: float | None = None
    apply_delay_s: float | None = None


class RealTimeStepper:
    """One world advanced on the wall clock; driven by :func:`serve_real_time`.

    Args:
        env: the world.
        real_time_factor: simulated seconds per wall-clock second (> 0).
    """

    def __init__(self, env: BaseEnv, real_time_factor: float = 1.0) -> None:
        factor = float(real_time_factor)
        if not (math.isfinite(factor) and factor > 0):
            raise ValueError(f"real_time_factor must be a finite number > 0, got {real_time_factor!r}")
        self.env = env
        self.factor = factor
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

    def next_deadline(self) -> float | None:
        """``time.monotonic()`` value at which the next substep boundary is due (None: nothing runs)."""
        return self._t0 + self._n * self.period if self.state == _RUNNING else None

    def describe(self) -> dict[str, Any]:
        return {"mode": "real_time", "real_time_factor": self.factor, "action_delay": 0}

    def timing(self) -> dict[str, Any]:
        """Pacing figures of this world (wall seconds)."""
        return {
            "pacing_error_s": self.pacing_error.summary(),
            "apply_delay_s": self.apply_delay.summary(),
            "overruns": self.overruns,
            "substeps": self.substeps,
            "period_s": self.period,
        }

    def clear_timing(self) -> None:
        self.pacing_error.clear()
        self.apply_delay.clear()
        self.overruns = 0
        self.substeps = 0

    # ------------------------------------------------------------ episode

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        """Synchronous reset; the clock starts with :meth:`start` once the reply is sent."""
        obs, info = self.env.reset(seed=seed, options=options)
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

    def step(self, action: Any) -> dict[str, Any]:
        raise RuntimeError("real-time steps are answered by serve_real_time, not by a direct call")

    def submit(self, identity: Any, seq: int, action: Any, now: float) -> list[Outgoing]:
        """A validated ``step`` request arrived at ``now``. Returns replies due at once."""
        if self.state == _FAILED:
            return [(identity, protocol.error_reply(seq, "scene", self._failure))]
        pending = _PendingStep(identity, seq, action, now)
        if self.state == _FROZEN:
            return [self._reply(pending, terminated=True)]
        # A newer request supersedes one still pending: its sender gave up on it.
        self._pending = pending
        return []

    def fail(self, exc: BaseException) -> list[Outgoing]:
        """The scene raised while advancing: stop this world until the next reset."""
        self.state = _FAILED
        self._failure = (
            f"{type(exc).__name__} in the scene while advancing in real time: {exc}; "
            f"reset the env to continue\n{traceback.format_exc()}"
        )
        pending, self._pending = self._pending, None
        if pending is None:
            return []
        return [(pending.identity, protocol.error_reply(pending.seq, "scene", self._failure))]

    def advance(self, now: float) -> list[Outgoing]:
        """Process the substep boundary that was due; ``now`` is the wall time it is processed.

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
                out.append(self._reply(pending, terminated=bool(terminated)))
            if terminated:
                self.state = _FROZEN
                return out
        pending = self._pending
        if pending is not None and pending.applied_sim_time is None:
            env.prepare_step(pending.action)
            self._held = pending.action
            pending.applied_sim_time = float(env.data.time)
            pending.apply_delay_s = time.monotonic() - pending.arrived
            self.apply_delay.add(pending.apply_delay_s)
        elif self._n % fs == 0:
            env.prepare_step(self._held)
        env.substep()
        self._n += 1
        self.substeps += 1
        return out

    def _reply(self, pending: _PendingStep, *, terminated: bool) -> Outgoing:
        """Answer ``pending`` with the current observation and what accumulated since the last reply."""
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
        return pending.identity, reply


# ---------------------------------------------------------------- server loop


def serve_real_time(server: Any) -> None:
    """Serve ``server`` (a :class:`~remoteenv.sim.server.RemoteControlledAgent`
    whose steppers are :class:`RealTimeStepper`) until it stops running.

    Requests are read whenever they arrive, also between substeps: ``reset``,
    ``handshake``, ``render`` and ``close`` are answered at once by the
    server's handlers, ``step`` is handed to its world's stepper, ``timing``
    returns each world's pacing figures. Waits use ``select`` on the socket's
    file descriptor with microsecond timeouts, so substeps fire close to
    their deadlines.
    """
    from remoteenv.sim.server import RequestError, validate_action

    steppers: list[RealTimeStepper] = list(server.steppers)
    for s in steppers:
        if not isinstance(s, RealTimeStepper):
            raise TypeError(f"serve_real_time needs RealTimeSteppers, got {type(s).__name__}")
    channels = list(server.channels)
    fds = [c.fd for c in channels]

    def send(out: list[Outgoing]) -> None:
        # An Outgoing's "identity" here is (channel, the channel's reply_to).
        for (channel, reply_to), reply in out:
            channel.send(reply_to, server.pack_reply(reply))

    def handle_step(identity: Any, msg: dict[str, Any], now: float) -> list[Outgoing]:
        seq = msg["seq"]
        world = msg.get("world", 0)
        if not isinstance(world, int) or isinstance(world, bool) or not 0 <= world < len(steppers):
            return [(identity, protocol.error_reply(
                seq, "protocol", f"world {world!r} out of range; this process hosts {len(steppers)}"))]
        stepper = steppers[world]
        if not stepper.has_reset:
            return [(identity, protocol.error_reply(
                seq, "state", f"step before reset on world {world} of instance {server.instance}"))]
        try:
            action = validate_action(stepper.env, msg.get("action"))
        except RequestError as exc:
            return [(identity, protocol.error_reply(seq, exc.kind, str(exc)))]
        return stepper.submit(identity, seq, action, now)

    def handle_timing(msg: dict[str, Any]) -> dict[str, Any]:
        reply = {"seq": msg["seq"], "ok": True, "worlds": [s.timing() for s in steppers]}
        if msg.get("clear"):
            for s in steppers:
                s.clear_timing()
        return reply

    def drain() -> None:
        """Read and handle every request that has arrived (non-blocking)."""
        for channel in channels:
            if server._running:
                drain_channel(channel)
            if channel.closed:  # the local pipe ended: the agent is gone
                server.pipe_closed()

    def drain_channel(channel: Any) -> None:
        for reply_to, frame in channel.receive_nowait():
            if not server._running:
                return
            now = time.monotonic()
            identity = (channel, reply_to)
            try:
                msg = protocol.decode_request(frame)
            except protocol.ProtocolError as exc:
                send([(identity, protocol.error_reply(-1, "protocol", str(exc)))])
                continue
            cmd = msg["cmd"]
            if cmd == "step":
                send(handle_step(identity, msg, now))
            elif cmd == "timing":
                send([(identity, handle_timing(msg))])
            else:
                send([(identity, server.handle(msg))])
                started = time.monotonic()
                for s in steppers:
                    if s.awaiting_clock:
                        s.start(started)

    last_check = time.monotonic()
    while server._running:
        drain()
        if not server._running:
            break
        now = time.monotonic()
        deadlines = [(d, s) for s in steppers if (d := s.next_deadline()) is not None]
        due = [s for d, s in sorted(deadlines, key=lambda p: p[0]) if d <= now]
        if due:
            for s in due:
                try:
                    send(s.advance(time.monotonic()))
                except Exception as exc:  # the scene raised: keep serving
                    send(s.fail(exc))
        else:
            timeout = _PARENT_CHECK_S
            if deadlines:
                timeout = min(timeout, min(d for d, _ in deadlines) - now)
            if timeout > _SPIN_S:
                # Wake a little early: the kernel's wake-up latency is then
                # absorbed by the short spin below instead of making us late.
                select.select(fds, [], [], timeout - _SPIN_S)
            # else: spin (the loop re-checks requests and the clock)
        now = time.monotonic()
        if now - last_check > _PARENT_CHECK_S:
            server.check_parent()
            last_check = now


__all__ = ["RealTimeStepper", "serve_real_time"]
