"""Lock-step: a world advances only when asked, optionally with an action delay.

Runs in the sim process. The same seed and the same actions give the same
trajectory in any process. :class:`LockStepper` steps one world;
:class:`LockStepping` is the server loop's strategy for all of them (no
clock: the loop just waits for requests). Both satisfy the interfaces of
:mod:`remoteenv.sim.stepping`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Sequence
from typing import Any

from remoteenv.sim.base_env import BaseEnv
from remoteenv.sim.channels import Channel, Outgoing


class LockStepper:
    """Advances one world by one control tick per ``step`` request.

    With ``action_delay=k`` the action received with step ``t`` takes effect
    at tick ``t + k`` (ticks counted from 0 after a reset); during the first
    ``k`` ticks the scene's default action is applied (see
    :meth:`BaseEnv.default_action`). The reply's ``info["applied_action"]``
    is then the action actually in force, or ``None`` for the default, and
    the info carries real-time mode's timing keys with their exact values:
    ``sim_time``, ``ticks_elapsed`` = 1, ``latency_ticks`` = k, ``latency_s``
    = k * dt and ``late`` = True (a whole tick runs before the action counts).
    """

    def __init__(self, env: BaseEnv, action_delay: int = 0) -> None:
        if action_delay < 0:
            raise ValueError(f"action_delay must be >= 0 ticks, got {action_delay}")
        self.env = env
        self.action_delay = int(action_delay)
        self.has_reset = False
        self._queue: deque[Any] = deque()

    def describe(self) -> dict[str, Any]:
        return {"mode": "lock_step", "action_delay": self.action_delay}

    def reset(self, *, seed: int | None, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.has_reset = True
        self._queue = deque([self.env.default_action()] * self.action_delay)
        return obs, info

    def submit(self, seq: int, action: Any, channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        """A ``step`` request: answered at once (see :meth:`step`)."""
        return self.step(action)

    def step(self, action: Any) -> dict[str, Any]:
        """One control tick with ``action`` (already checked); the reply's fields."""
        if self.action_delay:
            self._queue.append(action)
            action = self._queue.popleft()
        obs, reward, terminated, info = self.env.step(action)
        if self.action_delay:
            info = dict(info)
            info["applied_action"] = action
            # The timing keys of real-time mode, exact by construction here.
            info["sim_time"] = float(self.env.data.time)
            info["ticks_elapsed"] = 1
            info["latency_ticks"] = float(self.action_delay)
            info["latency_s"] = self.action_delay * self.env.dt
            info["late"] = True
        return {
            "obs": obs,
            "reward": float(reward),
            "terminated": bool(terminated),
            "truncated": False,
            "info": info,
        }


class LockStepping:
    """The loop strategy of a lock-step server: no deadlines, every reply at once.

    Args:
        envs: the worlds, one :class:`LockStepper` each.
        action_delay: control ticks between an action's arrival and its effect.
    """

    #: Lock-step has no clock to start.
    clock_waiting = False

    def __init__(self, envs: Sequence[BaseEnv], action_delay: int = 0) -> None:
        self._worlds = [LockStepper(env, action_delay=action_delay) for env in envs]

    @property
    def worlds(self) -> list[LockStepper]:
        return self._worlds

    def next_deadline(self) -> float | None:
        return None

    def start_clocks(self, now: float) -> None:
        pass

    def run_due(self, now: float) -> Iterator[Outgoing]:
        return iter(())


__all__ = ["LockStepper", "LockStepping"]
