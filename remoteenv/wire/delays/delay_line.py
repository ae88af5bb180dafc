"""Action and observation delays in lock-step: the exact semantics, as a pure engine.

No physics here: a stepper calls :class:`LockStepDelays` around each control
tick (``docs/delays.md`` states the same rules for readers, with worked
examples). Both processes may use it: the sim's lock-step stepper, and
in-process replays that must match it exactly.

Counting. After a reset, tick 0 is the reset itself and produces the reset
observation ``x_0``. Step ``t`` (``t = 1, 2, ...``, the ``t``-th ``step``
request of the episode) runs control tick ``t``: simulated time from
``(t - 1) * dt`` to ``t * dt`` after the reset, producing observation ``x_t``.

Actions. The action ``a_s`` sent with step ``s`` has a delay ``d_s`` drawn
when it is sent; it is due at tick ``s + d_s``. It *arrives* at tick ``A_s``:

- ``action_delivery="newest"`` (default): ``A_s = s + d_s``;
- ``action_delivery="in_order"`` (TCP-like): ``A_s = max(s + d_s, A_{s-1})``
  with ``A_0 = 0``: an action waits for every older one.

The action in force during tick ``n`` is the newest arrived one, ``a_{s*}``
with ``s* = max{s : A_s <= n}``; while none has arrived, the scene's default
action (counted as sent at step 0, ``s* = 0``). ``s*`` never decreases, so
an older action never overrides a newer one. An action that arrives when a
newer one has already arrived (at the same tick or before) never acts: it is
*dropped*, counted at its arrival tick (never earlier: nothing here counts a
delay before it has elapsed). Its age during tick ``n`` is
``alpha_n = n - s*`` (``alpha_0 = 0``: the default at the reset).

Observations. Observation ``x_n`` (``n >= 1``) has a delay ``o_n`` drawn when
tick ``n`` produces it and arrives at step ``B_n = n + o_n`` (``"newest"``) or
``B_n = max(n + o_n, B_{n-1})`` (``"in_order"``), ``B_0 = 0``. Step ``t``
returns the newest arrived observation ``x_{m_t}``, ``m_t = max{n : B_n <= t}``,
so the agent never goes back in time; ``x_0`` is there from the start (the
reset returns it undelayed). With a constant delay ``o`` that is
``x_max(0, t - o)`` under both rules. Its age is ``omega_t = t - m_t``.

What step ``t`` reports (:class:`StepDelays`), all known once tick ``t`` has
run: ``alpha_t`` and ``a_{s*}`` (the action in force during tick ``t``: it has
arrived); ``omega_t``; ``alpha_{m_t}`` and the action in force during tick
``m_t`` (that of the returned observation: Bouteiller et al.'s RDMDP state);
the latency of the action in force, ``A_{s*} - 1 - m_{s*-1}`` ticks (from
the observation the agent held when it sent it to the start of the tick it
arrived; None while the default acts). The delay drawn for the action just
sent (``sent_delay_ticks``) is kept for debugging and never leaves the engine.

Delayed rewards (``delayed_rewards=True``). Reward, ``terminated`` and the
scene's info travel with the observation: step ``t`` returns the reward of
the ticks its observation delivers, ``sum of r_n for m_{t-1} < n <= m_t``
(0 when no newer observation arrived; ticks whose observations were dropped
are delivered by the newer one), ``terminated`` of tick ``m_t`` and the
scene's info of tick ``m_t``. When tick ``N`` terminates, the physics
freezes: the steps after it run no physics and produce no observation
(reward 0); their actions still draw delays and arrive as usual, acting on
nothing; the episode ends at the step that delivers ``x_N``. Without it,
reward, ``terminated`` and the scene's info belong to tick ``t``.

Both directions are one structure, a :class:`DelayLine`: items sent in order,
each arriving at its own time, the newest arrived item in force.

Seeding. Delays are drawn from :class:`DelayStream` s, one per direction,
each with its own generator (:func:`delay_rng`): ``reset(seed=s)`` re-seeds
both and rewinds traces; a reset without a seed continues the streams (as
Gymnasium's ``np_random`` does), and the first draw without any seed takes
fresh entropy from the OS. Every step draws one action delay, and every tick
that runs physics one observation delay.
"""

from __future__ import annotations

import heapq
from collections import deque
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from remoteenv.wire.delays.channel_rules import IN_ORDER, NEWEST, ChannelRules
from remoteenv.wire.delays.delay_specs import TICKS, Delay, DelaySpec, as_delay

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
    """Items sent in order, each arriving at its own time; the newest arrived item is in force.

    Times are in any one unit (ticks or seconds). ``push(sent, due, item)``
    with ``sent`` strictly increasing and ``due >= sent``; ``advance(now)``
    with ``now`` never decreasing returns the item in force at ``now``. An
    item arrives at ``due`` (``rule="newest"``) or at ``max(due, arrival of
    the item sent before it)`` (``rule="in_order"``). An item that arrives
    when a newer one has arrived already (in the same call or before) never
    comes into force and is counted in :attr:`dropped` at that call: a count
    never depends on a due time that has not passed.
    """

    def __init__(self, initial: T, rule: str = NEWEST) -> None:
        if rule not in (NEWEST, IN_ORDER):
            raise ValueError(f"a delay line's rule is {NEWEST!r} or {IN_ORDER!r}, got {rule!r:.60}")
        self.rule = rule
        self.reset(initial)

    def reset(self, initial: T) -> None:
        """Forget everything in flight; ``initial`` is in force (as sent and arrived at time 0)."""
        self._current: T = initial
        self._current_sent: float = 0
        #: Arrival time of the item in force (0 for the initial one).
        self.current_arrival: float = 0
        self._flight: list[tuple[float, float, T]] = []  # a heap of (arrival, sent, item); sent is unique
        self._last_sent: float = 0
        self._last_arrival: float = 0
        self._now: float = 0
        #: Items that arrived and never came into force.
        self.dropped = 0
        #: Items that came into force (the initial one not counted).
        self.took_effect = 0
        #: Whether the last :meth:`advance` brought a newer item into force.
        self.changed = False

    def push(self, sent: float, due: float, item: T) -> float:
        """Send ``item`` at ``sent``, due at ``due``; returns its arrival time."""
        if sent <= self._last_sent:
            raise ValueError(f"items must be sent in order: sent {sent} after {self._last_sent}")
        if due < sent:
            raise ValueError(f"an item cannot be due ({due}) before it is sent ({sent})")
        arrival = due if self.rule == NEWEST else max(due, self._last_arrival)
        heapq.heappush(self._flight, (arrival, sent, item))
        self._last_sent = sent
        self._last_arrival = arrival
        return arrival

    def advance(self, now: float) -> tuple[T, float]:
        """``(item, sent)``: the item in force at ``now`` and when it was sent (0: the initial one)."""
        if now < self._now:
            raise ValueError(f"time cannot go back: advance({now}) after advance({self._now})")
        self._now = now
        self.changed = False
        arrived = 0
        newest: tuple[float, float, T] | None = None
        while self._flight and self._flight[0][0] <= now:
            entry = heapq.heappop(self._flight)
            arrived += 1
            if newest is None or entry[1] > newest[1]:
                newest = entry
        if newest is not None and newest[1] > self._current_sent:
            self.current_arrival, self._current_sent, self._current = newest
            self.changed = True
            self.took_effect += 1
            arrived -= 1
        self.dropped += arrived
        return self._current, self._current_sent

    @property
    def in_flight(self) -> int:
        """Items sent and not yet arrived."""
        return len(self._flight)


@dataclass(frozen=True)
class StepDelays:
    """What the delays did at one step (ticks, except ``obs_sim_time`` in seconds).

    Every field but ``sent_delay_ticks`` is known once the step's tick has run
    (see the module docstring); :meth:`info` holds only those."""

    #: The step, counted from 1 after the reset (= the control tick it ran).
    step: int
    #: Age of the action in force during this tick: ``step - action_step`` (alpha).
    action_delay_ticks: int
    #: The step that sent the action in force (0: the default action).
    action_step: int
    #: Delay drawn for the action sent with this step: scheduled, not yet
    #: elapsed, so never in :meth:`info` (for debugging and tests).
    sent_delay_ticks: int
    #: Age of the returned observation: ``step - obs_tick`` (omega).
    obs_delay_ticks: int
    #: The tick that produced the returned observation (0: the reset).
    obs_tick: int
    #: Sim time of the returned observation (seconds, as the stepper reported it).
    obs_sim_time: float
    #: Age of the action in force during tick ``obs_tick`` (0 for the reset observation).
    obs_action_delay_ticks: int
    #: The action in force during tick ``obs_tick`` (the default action's
    #: value while it acted; None for the reset observation, tick 0).
    obs_applied_action: Any
    #: The action in force during this tick (the default action's value while
    #: it acts: None for a scene whose default is "no action").
    applied_action: Any
    #: Ticks from the observation the agent held when it sent the action in
    #: force to the start of the tick that action arrived:
    #: ``A_s - 1 - m_{s-1}``; None while the default acts.
    latency_ticks: int | None
    #: True when the action in force arrived at this tick (it replaced an older one).
    action_took_effect: bool

    def info(self) -> dict[str, Any]:
        """The keys a lock-step reply's ``info`` carries (see ``docs/delays.md``)."""
        return {
            "action_delay_ticks": self.action_delay_ticks,
            "applied_action": self.applied_action,
            "action_took_effect": self.action_took_effect,
            "obs_delay_ticks": self.obs_delay_ticks,
            "obs_sim_time": self.obs_sim_time,
            "obs_action_delay_ticks": self.obs_action_delay_ticks,
            "obs_applied_action": self.obs_applied_action,
            "latency_ticks": self.latency_ticks,
        }


@dataclass(frozen=True)
class Delivered:
    """What a step hands the agent besides its :class:`StepDelays`.

    With ``delayed_rewards`` the reward, flag and scene info of the returned
    observation's ticks; otherwise those the stepper passed for this tick."""

    obs: Any
    reward: float
    terminated: bool
    scene_info: Any


@dataclass
class _Tick:
    """One physics tick's output, as it travels to the agent."""

    obs: Any
    sim_time: float
    alpha: int
    applied: Any
    reward: float = 0.0
    terminated: bool = False
    scene_info: Any = None


class LockStepDelays:
    """The action and observation delays of one world in lock-step.

    Per episode: :meth:`reset` with the reset observation; then per step
    :meth:`apply` (before the physics tick: which action is in force) and
    :meth:`observe` (after it: which observation to return), or
    :meth:`observe_frozen` instead of the physics while :attr:`frozen`.
    Observations are held by reference and may be returned at several
    steps: pass objects nobody mutates, and copy before handing them to code
    that does.

    Args:
        action_delay, obs_delay: the delay models (ticks).
        rules: delivery rules and delayed rewards (:class:`ChannelRules`; default: newest, not delayed).
    """

    def __init__(
        self, action_delay: DelaySpec | int = 0, obs_delay: DelaySpec | int = 0, rules: ChannelRules | None = None
    ) -> None:
        self.action_delay = as_delay(action_delay, TICKS)
        self.obs_delay = as_delay(obs_delay, TICKS)
        self.rules = rules if rules is not None else ChannelRules()
        self._action_stream = DelayStream(self.action_delay, ACTION_STREAM)
        self._obs_stream = DelayStream(self.obs_delay, OBS_STREAM)
        # An action travels with the tick of the observation the agent held when sending it.
        self._actions: DelayLine[tuple[Any, int]] = DelayLine((None, 0), self.rules.action_delivery)
        self._observations: DelayLine[_Tick] = DelayLine(_Tick(None, 0.0, 0, None), self.rules.obs_delivery)
        self.step = 0
        self._has_reset = False
        self._applied: tuple[int, int, Any, int | None, bool] | None = None
        self._obs_tick = 0
        self._undelivered: deque[tuple[int, float]] = deque()
        self._terminal_tick: int | None = None
        self._returned = _Tick(None, 0.0, 0, None)
        self._run = _RunCounts()

    @property
    def is_zero(self) -> bool:
        """True when neither direction ever delays anything."""
        return self.action_delay.is_zero and self.obs_delay.is_zero

    @property
    def frozen(self) -> bool:
        """With ``delayed_rewards``: the physics terminated this episode and its
        observations are still arriving; the stepper runs no physics."""
        return self._terminal_tick is not None

    @property
    def actions_dropped(self) -> int:
        """Actions of this episode that arrived and never took effect (a newer one had arrived)."""
        return self._actions.dropped

    def stats(self) -> dict[str, Any]:
        """Over every step since this engine was made (all episodes): ``steps``,
        ``mean_action_age_ticks`` (mean ``action_delay_ticks``), ``actions_sent``,
        ``actions_acted`` (that came into force), ``actions_dropped`` (arrived,
        never in force), ``actions_discarded`` (in flight at a reset) and
        ``never_acted_fraction`` (``1 - acted / sent``: dropped, discarded, and
        those still in flight)."""
        run = self._run
        acted = run.acted + self._actions.took_effect
        return {
            "steps": run.steps,
            "mean_action_age_ticks": run.age_sum / run.steps if run.steps else None,
            "actions_sent": run.steps,
            "actions_acted": acted,
            "actions_dropped": run.dropped + self._actions.dropped,
            "actions_discarded": run.discarded,
            "never_acted_fraction": 1.0 - acted / run.steps if run.steps else None,
        }

    def reset(self, obs: Any, sim_time: float, default_action: Any, seed: int | None = None) -> None:
        """Start an episode: nothing in flight, ``default_action`` in force,
        ``obs`` (the reset observation, tick 0) the newest. ``seed`` re-seeds
        both streams; None continues them."""
        if seed is not None:
            self._action_stream.seed(seed)
            self._obs_stream.seed(seed)
        if self._has_reset:
            self._run.end_episode(self._actions)
        self._actions.reset((default_action, 0))
        self._returned = _Tick(obs, float(sim_time), 0, None)
        self._observations.reset(self._returned)
        self.step = 0
        self._obs_tick = 0
        self._applied = None
        self._undelivered.clear()
        self._terminal_tick = None
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
        self._actions.push(self.step, self.step + delay, (action, self._obs_tick))
        (in_force, held_tick), sent = self._actions.advance(self.step)
        sent = int(sent)
        latency = None if sent == 0 else int(self._actions.current_arrival) - 1 - held_tick
        self._applied = (sent, delay, in_force, latency, self._actions.changed)
        self._run.steps += 1
        self._run.age_sum += self.step - sent
        return in_force, sent

    def observe(
        self, obs: Any, sim_time: float, reward: float = 0.0, terminated: bool = False, scene_info: Any = None
    ) -> tuple[Any, StepDelays]:
        """Hand in what this step's tick produced (the observation at
        ``sim_time``, and for delayed rewards its reward, flag and the scene's
        info); returns the observation to send back and what the delays did.
        :meth:`deliver` gives the reward, flag and info to send back."""
        if self._applied is None:
            raise RuntimeError("LockStepDelays.observe without apply")
        if self.frozen:
            raise RuntimeError(f"LockStepDelays.observe at step {self.step}: the physics froze, use observe_frozen")
        sent = self._applied[0]
        tick = _Tick(obs, float(sim_time), self.step - sent, self._applied[2], reward, terminated, scene_info)
        self._undelivered.append((self.step, float(reward)))
        if terminated and self.rules.delayed_rewards:
            self._terminal_tick = self.step
        self._observations.push(self.step, self.step + int(self._obs_stream.draw()), tick)
        return self._finish()

    def observe_frozen(self) -> tuple[Any, StepDelays]:
        """Instead of :meth:`observe` while :attr:`frozen`: no tick ran, nothing is produced."""
        if self._applied is None:
            raise RuntimeError("LockStepDelays.observe_frozen without apply")
        if not self.frozen:
            raise RuntimeError("LockStepDelays.observe_frozen while the physics runs: use observe")
        return self._finish()

    def _finish(self) -> tuple[Any, StepDelays]:
        assert self._applied is not None
        sent, delay, in_force, latency, took_effect = self._applied
        self._applied = None
        newest, tick = self._observations.advance(self.step)
        self._obs_tick = int(tick)
        self._returned = newest
        return newest.obs, StepDelays(
            step=self.step,
            action_delay_ticks=self.step - sent,
            action_step=sent,
            sent_delay_ticks=delay,
            obs_delay_ticks=self.step - self._obs_tick,
            obs_tick=self._obs_tick,
            obs_sim_time=newest.sim_time,
            obs_action_delay_ticks=newest.alpha,
            obs_applied_action=newest.applied,
            applied_action=in_force,
            latency_ticks=latency,
            action_took_effect=took_effect,
        )

    def deliver(self, reward: float, terminated: bool, scene_info: Any) -> Delivered:
        """The reward, ``terminated`` and scene info the step just observed returns:
        with ``delayed_rewards`` those of the returned observation (its ticks'
        summed reward, see the module docstring), else the arguments (this tick's)."""
        obs = self._returned.obs
        if not self.rules.delayed_rewards:
            return Delivered(obs, reward, terminated, scene_info)
        total = 0.0
        while self._undelivered and self._undelivered[0][0] <= self._obs_tick:
            total += self._undelivered.popleft()[1]
        return Delivered(obs, total, bool(self._returned.terminated), self._returned.scene_info)


class _RunCounts:
    """Counts over a :class:`LockStepDelays`' whole life (episodes before the current one)."""

    def __init__(self) -> None:
        self.steps = 0
        self.age_sum = 0
        self.acted = 0
        self.dropped = 0
        self.discarded = 0

    def end_episode(self, line: DelayLine[Any]) -> None:
        self.acted += line.took_effect
        self.dropped += line.dropped
        self.discarded += line.in_flight


__all__ = [
    "ACTION_STREAM",
    "ChannelRules",
    "DelayLine",
    "DelayStream",
    "Delivered",
    "IN_ORDER",
    "LINK_STREAM",
    "LockStepDelays",
    "NEWEST",
    "OBS_STREAM",
    "StepDelays",
    "delay_rng",
]
