"""Action and observation delays in lock-step: the exact semantics, as a pure engine.

No physics here: a stepper calls :class:`LockStepDelays` around each control
tick (``docs/delays.md`` states the same rules for readers). Both processes
may use it: the sim's lock-step stepper, and in-process replays that must
match it exactly.

Counting. After a reset, tick 0 is the reset itself and produces the reset
observation ``x_0``. Step ``t`` (``t = 1, 2, ...``, the ``t``-th ``step``
request of the episode) runs control tick ``t``: simulated time from
``(t - 1) * dt`` to ``t * dt`` after the reset, producing observation ``x_t``.

Actions. The action ``a_t`` sent with step ``t`` has a delay ``d_t`` drawn when
it is sent; it is due at tick ``t + d_t``. The action in force during tick
``n`` is the newest action due at or before ``n``; until one is due, the
scene's default action (counted as sent at step 0). An older action never
overrides a newer one: an action due no earlier than a newer one is dropped.

Observations. Observation ``x_n`` has a delay ``o_n`` drawn when tick ``n``
produces it; it arrives at step ``n + o_n``. Step ``t`` returns the newest
observation that has arrived, so the agent never goes back in time; ``x_0``
is there from the start (the reset returns it undelayed). With a constant
delay ``o`` that is ``x_max(0, t - o)``.

Both directions are one structure, a :class:`DelayLine`: items sent in order,
each due at its own time, the newest due item in force.

Seeding. Delays are drawn from :class:`DelayStream` s, one per direction,
each with its own generator (:func:`delay_rng`): ``reset(seed=s)`` re-seeds
both and rewinds traces; a reset without a seed continues the streams (as
Gymnasium's ``np_random`` does), and the first draw without any seed takes
fresh entropy from the OS.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from remoteenv.wire.delays.delays import TICKS, Delay, DelaySpec, as_delay

T = TypeVar("T")

#: ``spawn_key`` of each delay stream's :class:`numpy.random.SeedSequence`.
ACTION_STREAM = 1
OBS_STREAM = 2
#: Reserved for the real-time link delay (seconds).
LINK_STREAM = 3


def delay_rng(seed: int | None, stream: int) -> np.random.Generator:
    """The generator of one delay stream: PCG64 seeded with
    ``SeedSequence(seed, spawn_key=(stream,))``. It is independent of the
    scene's own generator (seeded with ``SeedSequence(seed)`` by Gymnasium)
    and of the other streams, so a delay never changes the scene's random
    draws nor the other direction's delays. ``seed=None``: OS entropy."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"a delay seed must be an int >= 0 or None, got {seed!r:.60}")
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(stream,))))


class DelayStream:
    """The draws of one spec in order: draw ``i`` after seeding is ``spec.sample(rng, i)``."""

    def __init__(self, spec: DelaySpec, stream: int) -> None:
        self.spec = spec
        self.stream = stream
        self._rng: np.random.Generator | None = None
        self.draws = 0

    def seed(self, seed: int | None) -> None:
        """Start the stream afresh (and rewind a trace)."""
        self._rng = delay_rng(seed, self.stream)
        self.draws = 0

    def draw(self) -> Delay:
        """The next delay (seeding from OS entropy if never seeded)."""
        if self._rng is None:
            self.seed(None)
        assert self._rng is not None
        value = self.spec.sample(self._rng, self.draws)
        self.draws += 1
        return value


class DelayLine(Generic[T]):
    """Items sent in order, each due at its own time; the newest due item is in force.

    Times are in any one unit (ticks or seconds). ``push(sent, due, item)``
    with ``sent`` strictly increasing and ``due >= sent``; ``advance(now)``
    with ``now`` never decreasing returns the item in force at ``now``. An
    item due no earlier than a newer one never comes into force and is
    counted in :attr:`dropped`: at ``push`` when a newer item is due no
    later, or at ``advance`` when a newer item became due in the same call.
    """

    def __init__(self, initial: T) -> None:
        self.reset(initial)

    def reset(self, initial: T) -> None:
        """Forget everything in flight; ``initial`` is in force (as sent at time 0)."""
        self._current: T = initial
        self._current_sent: float = 0
        self._flight: deque[tuple[float, float, T]] = deque()
        self._last_sent: float = 0
        self._now: float = 0
        self.dropped = 0

    def push(self, sent: float, due: float, item: T) -> None:
        if sent <= self._last_sent:
            raise ValueError(f"items must be sent in order: sent {sent} after {self._last_sent}")
        if due < sent:
            raise ValueError(f"an item cannot be due ({due}) before it is sent ({sent})")
        while self._flight and self._flight[-1][0] >= due:
            self._flight.pop()
            self.dropped += 1
        self._flight.append((due, sent, item))
        self._last_sent = sent

    def advance(self, now: float) -> tuple[T, float]:
        """``(item, sent)``: the item in force at ``now`` and when it was sent (0: the initial one)."""
        if now < self._now:
            raise ValueError(f"time cannot go back: advance({now}) after advance({self._now})")
        self._now = now
        arrived = 0
        while self._flight and self._flight[0][0] <= now:
            _, self._current_sent, self._current = self._flight.popleft()
            arrived += 1
        self.dropped += max(0, arrived - 1)
        return self._current, self._current_sent

    @property
    def in_flight(self) -> int:
        """Items sent and not yet due."""
        return len(self._flight)


@dataclass(frozen=True)
class StepDelays:
    """What the delays did at one step (ticks, except ``obs_sim_time`` in seconds)."""

    #: The step, counted from 1 after the reset (= the control tick it ran).
    step: int
    #: Age of the action in force during this tick: ``step - action_step``.
    action_delay_ticks: int
    #: The step that sent the action in force (0: the default action).
    action_step: int
    #: Delay drawn for the action sent with this step (due at ``step + sent_delay_ticks``).
    sent_delay_ticks: int
    #: Age of the returned observation: ``step - obs_tick``.
    obs_delay_ticks: int
    #: The tick that produced the returned observation (0: the reset).
    obs_tick: int
    #: Sim time of the returned observation (seconds, as the stepper reported it).
    obs_sim_time: float
    #: Ticks from the observation the agent held when sending this step's
    #: action (the previous step's) to the start of the tick the action is due:
    #: ``step + sent_delay_ticks - 1 - previous obs_tick``. Scheduled: a newer
    #: action may still overtake it.
    latency_ticks: int

    def info(self) -> dict[str, Any]:
        """The keys a lock-step reply's ``info`` carries."""
        return {
            "action_delay_ticks": self.action_delay_ticks,
            "obs_delay_ticks": self.obs_delay_ticks,
            "obs_sim_time": self.obs_sim_time,
            "latency_ticks": self.latency_ticks,
        }


class LockStepDelays:
    """The action and observation delays of one world in lock-step.

    Per episode: :meth:`reset` with the reset observation; then per step
    :meth:`apply` (before the physics tick: which action is in force) and
    :meth:`observe` (after it: which observation to return). Observations
    are held by reference and may be returned at several steps: pass objects
    nobody mutates, and copy before handing them to code that does.
    """

    def __init__(self, action_delay: DelaySpec | int = 0, obs_delay: DelaySpec | int = 0) -> None:
        self.action_delay = as_delay(action_delay, TICKS)
        self.obs_delay = as_delay(obs_delay, TICKS)
        self._action_stream = DelayStream(self.action_delay, ACTION_STREAM)
        self._obs_stream = DelayStream(self.obs_delay, OBS_STREAM)
        self._actions: DelayLine[Any] = DelayLine(None)
        self._observations: DelayLine[tuple[Any, float]] = DelayLine((None, 0.0))
        self.step = 0
        self._has_reset = False
        self._applied: tuple[int, int, int] | None = None
        self._obs_tick = 0

    @property
    def is_zero(self) -> bool:
        """True when neither direction ever delays anything."""
        return self.action_delay.is_zero and self.obs_delay.is_zero

    @property
    def actions_dropped(self) -> int:
        """Actions overtaken by a newer one this episode (they never took effect)."""
        return self._actions.dropped

    def reset(self, obs: Any, sim_time: float, default_action: Any, seed: int | None = None) -> None:
        """Start an episode: nothing in flight, ``default_action`` in force,
        ``obs`` (the reset observation, tick 0) the newest. ``seed`` re-seeds
        both streams; None continues them."""
        if seed is not None:
            self._action_stream.seed(seed)
            self._obs_stream.seed(seed)
        self._actions.reset(default_action)
        self._observations.reset((obs, float(sim_time)))
        self.step = 0
        self._obs_tick = 0
        self._applied = None
        self._has_reset = True

    def apply(self, action: Any) -> tuple[Any, int]:
        """Send ``action`` with the next step; ``(action in force, step that sent
        it)`` for this step's tick (step 0: the default action)."""
        if not self._has_reset:
            raise RuntimeError("LockStepDelays.apply before reset")
        if self._applied is not None:
            raise RuntimeError(f"LockStepDelays.apply twice at step {self.step}: call observe first")
        self.step += 1
        delay = int(self._action_stream.draw())
        self._actions.push(self.step, self.step + delay, action)
        in_force, sent = self._actions.advance(self.step)
        self._applied = (int(sent), delay, self.step + delay - 1 - self._obs_tick)
        return in_force, int(sent)

    def observe(self, obs: Any, sim_time: float) -> tuple[Any, StepDelays]:
        """Hand in the observation this step's tick produced (at ``sim_time``);
        returns the observation to send back and what the delays did."""
        if self._applied is None:
            raise RuntimeError("LockStepDelays.observe without apply")
        action_step, sent_delay, latency = self._applied
        self._applied = None
        delay = int(self._obs_stream.draw())
        self._observations.push(self.step, self.step + delay, (obs, float(sim_time)))
        (returned, returned_time), tick = self._observations.advance(self.step)
        self._obs_tick = int(tick)
        return returned, StepDelays(
            step=self.step,
            action_delay_ticks=self.step - action_step,
            action_step=action_step,
            sent_delay_ticks=sent_delay,
            obs_delay_ticks=self.step - self._obs_tick,
            obs_tick=self._obs_tick,
            obs_sim_time=returned_time,
            latency_ticks=latency,
        )


__all__ = [
    "ACTION_STREAM",
    "DelayLine",
    "DelayStream",
    "LINK_STREAM",
    "LockStepDelays",
    "OBS_STREAM",
    "StepDelays",
    "delay_rng",
]
