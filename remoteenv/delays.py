"""Delay specs for latency experiments: ``remoteenv.delays.Uniform(0, 3)`` and friends.

The public path of :mod:`remoteenv.wire.delays.delay_specs` (the specs, in ticks or
seconds), :mod:`remoteenv.wire.delays.delay_line` (the lock-step semantics) and
:mod:`remoteenv.wire.delays.channel_rules` (delivery rules, delayed rewards).
``docs/delays.md`` states what a delay of ``k`` ticks means.

Users build specs in the agent process; a sim rebuilds them from their wire form (both processes use the modules behind this face).
"""

from remoteenv.wire.delays.channel_rules import IN_ORDER, NEWEST, ChannelRules
from remoteenv.wire.delays.delay_line import DelayLine, DelayStream, LockStepDelays, StepDelays, delay_rng
from remoteenv.wire.delays.delay_specs import (
    MAX_DELAY_S,
    MAX_DELAY_TICKS,
    SECONDS,
    TICKS,
    Categorical,
    Constant,
    DelaySpec,
    Trace,
    Uniform,
    as_delay,
    delay_from_wire,
)

__all__ = [
    "IN_ORDER",
    "NEWEST",
    "Categorical",
    "ChannelRules",
    "Constant",
    "DelayLine",
    "DelaySpec",
    "DelayStream",
    "LockStepDelays",
    "MAX_DELAY_S",
    "MAX_DELAY_TICKS",
    "SECONDS",
    "StepDelays",
    "TICKS",
    "Trace",
    "Uniform",
    "as_delay",
    "delay_from_wire",
    "delay_rng",
]
