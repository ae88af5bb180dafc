"""The channel rules of lock-step delays: how delayed items are delivered, and what travels with an observation.

Both processes use this module: the agent builds :class:`ChannelRules` from
``action_delivery=``, ``obs_delivery=`` and ``delayed_rewards=``, the
launcher writes their wire form (:meth:`ChannelRules.to_wire`) into the
delay file (:mod:`remoteenv.wire.delays.delay_file`), and the sim rebuilds
them with :meth:`ChannelRules.from_wire`, which treats the map as hostile.
The rules themselves, tick by tick, are :mod:`remoteenv.wire.delays.delay_line`'s.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from remoteenv.wire.wire_errors import ProtocolError, short_repr

#: The newest item that has arrived is in force (an older one arriving later is dropped).
NEWEST = "newest"
#: Items arrive in the order sent (TCP-like): an item waits for every older one.
IN_ORDER = "in_order"
DELIVERY_RULES = (NEWEST, IN_ORDER)


@dataclass(frozen=True)
class ChannelRules:
    """How a lock-step world's delays deliver actions and observations.

    Attributes:
        action_delivery: ``"newest"`` (default): the action sent at step ``s``
            arrives at tick ``s + d_s``; ``"in_order"``: at
            ``max(s + d_s, arrival of the action sent at s - 1)``. Under both,
            the newest arrived action is in force.
        obs_delivery: the same choice for observations (``n + o_n``, or
            ``max(n + o_n, arrival of x_{n-1})``).
        delayed_rewards: reward, ``terminated`` and the scene's info travel
            with the observation: a step returns the reward of the ticks whose
            observations it delivers, and the episode ends at the step that
            delivers the terminal observation (the physics freezes meanwhile).
    """

    action_delivery: str = NEWEST
    obs_delivery: str = NEWEST
    delayed_rewards: bool = False

    def __post_init__(self) -> None:
        for name in ("action_delivery", "obs_delivery"):
            value = getattr(self, name)
            if value not in DELIVERY_RULES:
                raise ValueError(f"{name} must be one of {DELIVERY_RULES}, got {short_repr(value)}")
        if not isinstance(self.delayed_rewards, bool):
            raise ValueError(f"delayed_rewards must be True or False, got {short_repr(self.delayed_rewards)}")

    @property
    def is_default(self) -> bool:
        """True for the default rules (newest delivery both ways, rewards of the tick run)."""
        return self == ChannelRules()

    def to_wire(self) -> dict[str, Any]:
        """The rules as a plain map (every field)."""
        return {
            "action_delivery": self.action_delivery,
            "obs_delivery": self.obs_delivery,
            "delayed_rewards": self.delayed_rewards,
        }

    @classmethod
    def from_wire(cls, value: Any) -> ChannelRules:
        """Rebuild rules from :meth:`to_wire`'s map; ProtocolError for anything else."""
        if not isinstance(value, Mapping):
            raise ProtocolError(f"channel rules must be a map, got {type(value).__name__}")
        known = ("action_delivery", "obs_delivery", "delayed_rewards")
        unknown = sorted(str(k) for k in value if k not in known)
        if unknown:
            raise ProtocolError(f"channel rules have unknown keys {short_repr(unknown[:10])}; expected some of {known}")
        try:
            return cls(**dict(value))
        except (TypeError, ValueError) as exc:
            raise ProtocolError(f"channel rules: {short_repr(str(exc))}") from None


__all__ = ["DELIVERY_RULES", "IN_ORDER", "NEWEST", "ChannelRules"]
