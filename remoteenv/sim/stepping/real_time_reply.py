"""What a real-time step's reply says: the waiting request and what happened since the last reply.

Runs in the sim process, for :class:`~remoteenv.sim.stepping.real_time_world.RealTimeStepper`
(the info keys are listed in :mod:`remoteenv.sim.stepping.real_time`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from remoteenv.sim.transport.channels import Channel


@dataclass
class PendingStep:
    """A ``step`` request waiting for its reply."""

    channel: Channel | None
    reply_to: Any
    seq: int
    action: Any
    arrived: float  # clock time when the request was handed over
    link_delay: float = 0.0  # emulated link: wall seconds it is held back after arriving
    applied_sim_time: float | None = None
    applied_substep: int | None = None
    apply_delay_s: float | None = None
    apply_at: int = 0  # replay: the substep at which the action takes effect


class SinceReply:
    """The ticks scored since the last reply (or the reset), and the observation they ended on."""

    def __init__(self) -> None:
        self.start(None, 0.0)

    def start(self, obs: Any, sim_time: float, substep: int = 0) -> None:
        """Nothing accumulated; the agent's last observation is ``obs``, of ``sim_time`` and ``substep``."""
        self.reward = 0.0
        self.ticks = 0
        self.obs = obs
        self.info: dict[str, Any] = {}
        self.obs_time = sim_time
        self.obs_substep = substep

    def add_tick(self, obs: Any, reward: Any, info: dict[str, Any]) -> None:
        self.obs, self.info = obs, info
        self.reward += float(reward)
        self.ticks += 1

    def reply(
        self,
        pending: PendingStep,
        *,
        terminated: bool,
        sim_time: float,
        substep: int,
        frame_skip: int,
        overruns: int,
        link: bool = False,
    ) -> dict[str, Any]:
        """The reply to ``pending`` at ``sim_time`` (substep ``substep``); starts over
        afterwards. ``link``: the world emulates a link (then ``link_delay_s`` is reported)."""
        applied = pending.applied_sim_time
        info = dict(self.info)
        info.update(
            sim_time=sim_time,
            substep=substep,
            action_sim_time=applied,
            action_substep=pending.applied_substep,
            ticks_elapsed=self.ticks,
            latency_s=None if applied is None else applied - self.obs_time,
            latency_ticks=None
            if pending.applied_substep is None
            else (pending.applied_substep - self.obs_substep) / frame_skip,
            late=applied is None or self.ticks > 1,
            apply_delay_s=pending.apply_delay_s,
            pacing_overruns=overruns,
        )
        if link:
            info["link_delay_s"] = pending.link_delay
        reply = {
            "seq": pending.seq,
            "ok": True,
            "obs": self.obs,
            "reward": self.reward,
            "terminated": terminated,
            "truncated": False,
            "info": info,
        }
        self.start(self.obs, sim_time, substep)
        return reply


__all__ = ["PendingStep", "SinceReply"]
