"""How a world advances when asked: lock-step, optionally with an action delay.

Runs in the sim process. Lock-step means the world advances only on a ``step``
request, so the same seed and the same actions give the same trajectory in
any process.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from remoteenv.sim.base_env import BaseEnv


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

    def step(self, action: Any) -> dict[str, Any]:
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


def make_stepper(
    env: BaseEnv, *, real_time: bool = False, real_time_factor: float = 1.0, action_delay: int = 0
) -> Any:
    """The stepper for one world in the requested mode."""
    if real_time:
        if action_delay:
            raise ValueError("action_delay is the lock-step twin of real_time; use one or the other")
        from remoteenv.sim.real_time import RealTimeStepper

        return RealTimeStepper(env, real_time_factor=real_time_factor)
    return LockStepper(env, action_delay=action_delay)
