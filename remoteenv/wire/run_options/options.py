"""The run options: how a sim's worlds run, built and checked once, carried whole.

Both processes use it. The agent builds one :class:`RunOptions` from an
env's keyword arguments (``gymnasium.make``, :class:`remoteenv.RemoteVectorEnv`,
:class:`remoteenv.Launcher`); it travels whole in the
:class:`~remoteenv.agent.launch.sim_group.LaunchSpec` to the launcher (or in
the Ray ``SimSpec`` to the actor on a node), which hands it to the sim as
its command line and delay file (:meth:`RunOptions.scene_arguments`,
:meth:`RunOptions.delay_file_text`). The sim rebuilds one from them
(:func:`remoteenv.sim.scene_main.run_options_from_arguments`) and gives it
whole to :class:`~remoteenv.sim.serving.sim_server.RemoteControlledAgent`,
which picks the stepping strategy and gives each world's stepper its share.

What the options mean (``docs/real-time.md``, ``docs/delays.md``):

- lock-step (default) or ``real_time`` (a paced clock, ``real_time_factor``
  simulated seconds per wall-clock second, in the regime ``real_time_mode``,
  :mod:`~remoteenv.wire.run_options.real_time_modes`);
- lock-step's delays, in control ticks: ``action_delay``, ``obs_delay``, and
  their channel rules ``action_delivery``, ``obs_delivery``,
  ``delayed_rewards`` (:class:`~remoteenv.wire.delays.channel_rules.ChannelRules`);
- real time's emulated link, in wall seconds: ``link_delay``;
- lock-step's physics threads per sim process, ``physics_threads`` (None:
  the sim's default, :func:`remoteenv.sim.stepping.batch_physics.default_threads`),
  which the vector env's default layout sets (:mod:`remoteenv.agent.vector.vector_layout`);
  a world's trajectory does not depend on it.

One mode's delays are refused in the other, and the rules without a lock-step
delay to act on are moot (not written to the sim). Every check is here, so a
bad combination fails in the agent before a process starts, with the same
message a sim started by hand gives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from remoteenv.wire.delays.channel_rules import NEWEST, ChannelRules
from remoteenv.wire.delays.delay_file import delay_file_text
from remoteenv.wire.delays.delay_specs import SECONDS, TICKS, DelaySpec, as_delay
from remoteenv.wire.run_options.real_time_modes import ELASTIC, check_real_time_mode


def _tick_delay(value: DelaySpec | int, name: str) -> DelaySpec:
    """``value`` as a spec in ticks; a negative int is refused naming ``name``."""
    if not isinstance(value, DelaySpec) and int(value) < 0:
        raise ValueError(f"{name} must be >= 0 ticks, got {value}")
    try:
        return as_delay(value, TICKS)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


@dataclass(frozen=True)
class RunOptions:
    """How a sim's worlds run (see the module docstring); checked when made.

    Attributes:
        real_time: run physics on a paced wall clock.
        real_time_factor: real time; simulated seconds per wall-clock second
            (a finite number > 0).
        real_time_mode: real time; the regime, :data:`~remoteenv.wire.run_options.real_time_modes.ELASTIC`
            (default) or :data:`~remoteenv.wire.run_options.real_time_modes.FIXED_STEP`.
        action_delay: lock-step; an action takes effect this many control ticks
            later (an int, or a delay spec in ticks; kept as given, see
            :attr:`action_delay_spec`).
        obs_delay: lock-step; observations arrive this many ticks late (the same).
        link_delay: real time; an emulated network's extra delay per action in
            wall seconds (a number, or a spec with ``unit="s"``); None: no
            emulated link.
        action_delivery, obs_delivery, delayed_rewards: lock-step, with a
            delay: the channel rules (:attr:`channel`).
        physics_threads: lock-step; threads each sim process steps its
            worlds' physics on (an int >= 1; None: the sim's default).
    """

    real_time: bool = False
    real_time_factor: float = 1.0
    real_time_mode: str = ELASTIC
    action_delay: DelaySpec | int = 0
    obs_delay: DelaySpec | int = 0
    link_delay: DelaySpec | float | None = None
    action_delivery: str = NEWEST
    obs_delivery: str = NEWEST
    delayed_rewards: bool = False
    physics_threads: int | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "real_time", bool(self.real_time))
        if self.physics_threads is not None:
            if type(self.physics_threads) is not int or self.physics_threads < 1:
                raise ValueError(f"physics_threads must be an int >= 1 or None, got {self.physics_threads!r:.40}")
            if self.real_time:
                raise ValueError("physics_threads is lock-step's: a real-time sim steps one world")
        _tick_delay(self.action_delay, "action_delay")  # the delays are kept as given, once checked
        _tick_delay(self.obs_delay, "obs_delay")
        if self.link_delay is not None:
            as_delay(self.link_delay, SECONDS)
        rules = self.channel  # checks the rules' values
        check_real_time_mode(self.real_time_mode)
        if self.real_time:
            factor = float(self.real_time_factor)
            if not (math.isfinite(factor) and factor > 0):
                raise ValueError(f"real_time_factor must be a finite number > 0, got {self.real_time_factor!r}")
            set_(self, "real_time_factor", factor)
            if self.lock_step_delayed:
                raise ValueError(
                    "action_delay and obs_delay are lock-step's reproducible twin of real_time; use one or the "
                    "other (an emulated link in real time is link_delay)"
                )
            if not rules.is_default:
                raise ValueError(
                    "action_delivery, obs_delivery and delayed_rewards are rules of lock-step's delays; "
                    "real time has none of them"
                )
            return
        if self.real_time_mode != ELASTIC:
            raise ValueError(f"real_time_mode={self.real_time_mode!r} is a real-time regime: add real_time=True")
        if self.link_delayed:
            raise ValueError(
                "link_delay emulates a network in real time (real_time=True); in lock-step use action_delay/obs_delay"
            )

    @property
    def channel(self) -> ChannelRules:
        """The channel rules of lock-step's delays (delivery both ways, delayed rewards)."""
        return ChannelRules(self.action_delivery, self.obs_delivery, self.delayed_rewards)

    @property
    def action_delay_spec(self) -> DelaySpec:
        """:attr:`action_delay` as a spec in ticks (an int ``k`` is ``Constant(k)``)."""
        return as_delay(self.action_delay, TICKS)

    @property
    def obs_delay_spec(self) -> DelaySpec:
        """:attr:`obs_delay` as a spec in ticks."""
        return as_delay(self.obs_delay, TICKS)

    @property
    def lock_step_delayed(self) -> bool:
        """Whether an action or observation delay can be other than 0."""
        return not (self.action_delay_spec.is_zero and self.obs_delay_spec.is_zero)

    @property
    def link_delayed(self) -> bool:
        """Whether the emulated link delays anything."""
        return self.link_delay is not None and not as_delay(self.link_delay, SECONDS).is_zero

    @property
    def timed_steps(self) -> bool:
        """Whether steps carry the timing keys: real time, or a lock-step delay."""
        return self.real_time or self.lock_step_delayed

    def scene_arguments(self) -> list[str]:
        """The scene command line's flags for these options (the delays go in
        the delay file, :meth:`delay_file_text`): in lock-step, the physics threads when set."""
        if not self.real_time:
            return [] if self.physics_threads is None else ["--physics-threads", str(self.physics_threads)]
        flags = ["--real-time", "--real-time-factor", repr(float(self.real_time_factor))]
        if self.real_time_mode != ELASTIC:
            flags += ["--real-time-mode", self.real_time_mode]
        return flags

    def delay_file_text(self) -> str | None:
        """The text of each sim's delay file (see :mod:`remoteenv.wire.delays.delay_file`):
        every delay's wire form in JSON, the channel rules where a lock-step
        delay makes them matter; None without delays."""
        return delay_file_text(self.action_delay, self.obs_delay, self.link_delay, self.channel)

    def describe(self) -> dict[str, Any]:
        """The options as plain data (JSON-able), for records and messages."""
        return {
            "real_time": self.real_time,
            "real_time_factor": self.real_time_factor,
            "real_time_mode": self.real_time_mode,
            "action_delay": self.action_delay_spec.to_wire(),
            "obs_delay": self.obs_delay_spec.to_wire(),
            "link_delay": None if self.link_delay is None else as_delay(self.link_delay, SECONDS).to_wire(),
            **self.channel.to_wire(),
        }


__all__ = ["RunOptions"]
