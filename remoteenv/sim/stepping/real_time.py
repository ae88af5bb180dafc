"""Real-time mode: physics paced to the wall clock while the agent thinks.

Runs in the sim process. :class:`RealTimeStepper` owns the schedule and
action handling of one world; :class:`RealTimeStepping` is the server loop's
strategy for all of them (see :mod:`remoteenv.sim.stepping.interfaces`): the loop
answers requests between physics substeps and fires each world's substeps on
their deadlines. Both read time from an injected clock (``time.monotonic`` in
a sim process), in seconds.

Semantics:

- Physics substep ``n`` of an episode (``model.opt.timestep`` simulated
  seconds) runs at the wall-clock deadline ``t0 + n * timestep / factor``,
  where ``t0`` is read just before the reply to ``reset`` is sent. Deadlines
  are absolute, so waiting errors never add up to drift; a late process runs
  the missed substeps back to back to catch up (up to
  :data:`~remoteenv.sim.stepping.real_time_pacing.CATCH_UP_LIMIT_S` behind;
  beyond that the clock slips: the boundary is due when it is processed).
- An action takes effect at the first substep boundary whose *deadline* is
  at or after the moment the sim read it (plus the emulated link's delay),
  and is held until the next one replaces it; after a reset the scene's
  :meth:`~remoteenv.sim.scene.base_env.BaseEnv.default_action` is held.
  Boundaries processed late (a catch-up) run with the action that had been
  read by their deadline, never with one read while they were processed, so
  no action acts at a sim time that preceded its arrival, and no latency
  is below the time from the observation's reply to the action's arrival.
- Control ticks are ``frame_skip`` substeps, as in lock-step. The reply to a
  ``step`` is sent at the end of the first tick in which its action was in
  force (the ``"elastic"`` regime, the default); its reward is the sum over all ticks since the previous reply; its
  scene ``info`` is that of the last tick. When a tick terminates the
  episode, the world freezes there: nothing advances until the next reset,
  and a pending or later ``step`` is answered at once with ``terminated``.
- Before the first reset, and while frozen, nothing advances.

Fixed step (``real_time_mode="fixed_step"``, rtgym's regime): an action
takes effect only at a control-tick boundary, the first one whose deadline
is at or after its arrival (never boundary 0), and the reply is sent at that boundary, with the
observation of that boundary: an agent that answers within a tick gets one
tick per step and a latency of exactly one tick; one that overruns gets a
longer step (``ticks_elapsed > 1``, ``late``). Everything else is as above.

Replay: a reset whose options carry a replay schedule replays a recorded
episode without the clock (see :mod:`remoteenv.sim.stepping.real_time_replay`).

Emulated link: with ``link_delay`` (seconds: a number or a
:class:`~remoteenv.wire.delays.delay_specs.DelaySpec` with ``unit="s"``, e.g.
``Uniform(0.005, 0.015, unit="s")`` for jitter) every arriving action is
held back by a delay drawn for it, on top of the real one, before it can
take effect at the next substep: the extra round trip of a longer network,
put on the action's way in (its reply, sent once the action was in force,
is late by the same amount). Draws come from the link stream
(:data:`~remoteenv.wire.delays.delay_line.LINK_STREAM`), seeded by
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
``substep``           physics substeps from the episode's reset to the
                      returned observation (an int).
``action_substep``    physics substeps from the reset to the one at which
                      the step's action took effect (None if it never did):
                      what an exact replay needs.
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
``link_delay_s``      with ``link_delay`` only: the emulated link delay
                      drawn for this step's action (wall seconds; 0.0 for
                      a step answered at once by a frozen world).
``pacing_overruns``   running count, for this world since the process
                      started, of substeps that ran more than one substep
                      period (``timestep / factor`` wall seconds) late.

The agent adds ``wall_round_trip_s`` (see :mod:`remoteenv.remote_env`).
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from typing import Any

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.stepping.real_time_world import REAL_TIME_OPTIONS, Clock, RealTimeStepper
from remoteenv.sim.transport.channels import Channel, Outgoing
from remoteenv.wire.run_options.options import RunOptions


class RealTimeStepping:
    """The loop strategy of a real-time server: one clock, each world on its own schedule.

    Args:
        envs: the worlds, one :class:`RealTimeStepper` each.
        run: the real-time options of every world (factor, regime, emulated
            link; see :class:`RealTimeStepper`); each world draws its link
            delays from its own stream.
        clock: where wall time comes from (seconds, monotonic).
        seed: launch seed of world 0 (world ``w``: ``seed + w``) for the link streams.
    """

    def __init__(
        self,
        envs: Sequence[BaseEnv],
        run: RunOptions = REAL_TIME_OPTIONS,
        clock: Clock = time.monotonic,
        seed: int | None = None,
    ) -> None:
        self.clock = clock
        self._worlds = [
            RealTimeStepper(env, run, clock=clock, seed=None if seed is None else seed + w)
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
