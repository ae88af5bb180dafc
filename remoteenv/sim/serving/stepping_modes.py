"""Which stepping strategy a sim server runs, and the commands only that mode answers.

Runs in the sim process.
"""

from __future__ import annotations

from collections.abc import Sequence

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.serving.commands import Handler
from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.interfaces import Stepping
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.sim.stepping.real_time import Clock, RealTimeStepping
from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.delay_specs import DelaySpec
from remoteenv.wire.run_options.real_time_modes import ELASTIC


def stepping_and_commands(
    envs: Sequence[BaseEnv],
    instance: int,
    *,
    real_time: bool,
    real_time_factor: float,
    real_time_mode: str = ELASTIC,
    action_delay: DelaySpec | int,
    obs_delay: DelaySpec | int,
    link_delay: DelaySpec | float | None,
    seed: int | None,
    clock: Clock,
    channel: ChannelRules | None = None,
) -> tuple[Stepping, dict[str, Handler]]:
    """The stepping of the requested mode and the commands only that mode answers:
    ``timing``, ``pause`` and ``resume`` in real time, ``reset_batch``,
    ``step_batch`` (and ``shared_batch`` where the spaces allow) in lock-step."""
    if real_time:
        for name, value in (("action_delay", action_delay), ("obs_delay", obs_delay)):
            if isinstance(value, DelaySpec) and not value.is_zero or not isinstance(value, DelaySpec) and value:
                raise ValueError(
                    f"{name} is lock-step's reproducible twin of real_time; use one or the other "
                    "(an emulated link in real time is link_delay)"
                )
        if channel is not None and not channel.is_default:
            raise ValueError(
                "delivery rules and delayed_rewards are lock-step's (action_delay/obs_delay), not real time's"
            )
        real = RealTimeStepping(
            envs, real_time_factor, clock=clock, link_delay=link_delay, seed=seed, mode=real_time_mode
        )
        return real, {"timing": real.timing, "pause": real.pause, "resume": real.resume}
    if real_time_mode != ELASTIC:
        raise ValueError(f"real_time_mode={real_time_mode!r} is a real-time regime: launch with real_time=True")
    if link_delay:
        raise ValueError("link_delay emulates a network in real time; in lock-step use action_delay/obs_delay")
    lock = LockStepping(envs, action_delay=action_delay, obs_delay=obs_delay, seed=seed, rules=channel)
    batch = BatchCommands(lock.worlds, envs[0].action_space, instance)
    return lock, batch.handlers()
