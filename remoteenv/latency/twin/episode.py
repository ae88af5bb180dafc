"""One recorded real-time episode, as its twins need it (see :mod:`remoteenv.latency.twin`). Runs in the agent process."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from remoteenv.latency.twin.recorded_env import RecordedEnv
from remoteenv.latency.twin.trace import twin_latency, twin_values
from remoteenv.wire.delays.delay_specs import Trace
from remoteenv.wire.run_options.real_time_modes import ELASTIC


@dataclass
class RecordedEpisode:
    """One real-time episode, as its twin needs it and as it went.

    Attributes:
        seed: the seed of this episode's reset, or of the last seeded reset
            before it (None: never seeded).
        resets_after_seed: unseeded resets from that seeded reset up to and
            including this episode's (0 when this episode's reset had the
            seed). The twin repeats them to reach the same scene RNG state
            (the scene must draw from its RNG only when it resets, as the
            shipped scenes do).
        ticks_elapsed: each step's ``info["ticks_elapsed"]``.
        latency_ticks: each step's ``info["latency_ticks"]`` (None when the
            action never took effect).
        rewards: each step's reward (summed over its ticks by the sim).
        terminated, truncated: how the episode ended (both False if a reset
            cut it short).
        rounding: the default of :meth:`values` and :meth:`trace`.
        mode: the real-time regime the episode ran in (``"elastic"`` or ``"fixed_step"``).
        action_substeps: per step, the physics substep (counted from the
            reset) at which its action took effect (``info["action_substep"]``),
            or for an action that never did, the substep at which the episode
            ended (``info["substep"]``): the exact twin's schedule.
        obs_digests: :func:`~remoteenv.latency.twin.digest.obs_digest` of the
            reset's observation, then of each step's.
        unreplayable: why the exact twin cannot replay this episode (None: it can).
        link_delays: with an emulated link, each step's ``info["link_delay_s"]``
            (wall seconds), which the twin reports again; None: no link.
        env: the env it ran in (:class:`~remoteenv.latency.twin.recorded_env.RecordedEnv`;
            None: unknown, e.g. a recording of format version 1).
    """

    seed: int | None
    resets_after_seed: int
    ticks_elapsed: list[int] = field(default_factory=list)
    latency_ticks: list[float | None] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    terminated: bool = False
    truncated: bool = False
    rounding: str = "nearest"
    mode: str = ELASTIC
    action_substeps: list[int] = field(default_factory=list)
    obs_digests: list[str] = field(default_factory=list)
    unreplayable: str | None = None
    link_delays: list[float] | None = None
    env: RecordedEnv | None = None

    @property
    def steps(self) -> int:
        """Real-time steps (decisions) of the episode."""
        return len(self.ticks_elapsed)

    @property
    def ticks(self) -> int:
        """Control ticks the episode ran: the length of its trace."""
        return int(sum(self.ticks_elapsed))

    @property
    def episode_return(self) -> float:
        return float(sum(self.rewards))

    def values(self, rounding: str | None = None) -> list[int]:
        """The twin's trace values (:func:`~remoteenv.latency.twin.twin_values`)."""
        return twin_values(self.ticks_elapsed, self.latency_ticks, rounding or self.rounding)

    def trace(self, rounding: str | None = None) -> Trace:
        """The twin's action delay: ``Trace(values)`` in ticks."""
        return Trace(self.values(rounding))

    def summary(self, rounding: str | None = None) -> dict[str, Any]:
        """Plain figures of the episode (JSON-able); latencies in ticks."""
        rounding = rounding or self.rounding
        pairs = [(t, v) for t, v in zip(self.ticks_elapsed, self.latency_ticks) if v is not None]
        real = np.array([v for _, v in pairs], dtype=np.float64)
        twin = np.array([twin_latency(t, v, rounding) for t, v in pairs], dtype=np.float64)
        return {
            "seed": self.seed,
            "resets_after_seed": self.resets_after_seed,
            "steps": self.steps,
            "ticks": self.ticks,
            "return": self.episode_return,
            "terminated": self.terminated,
            "truncated": self.truncated,
            "late_steps": int(sum(t > 1 for t in self.ticks_elapsed)),
            "unapplied_steps": int(sum(v is None for v in self.latency_ticks)),
            "mean_latency_ticks": float(real.mean()) if real.size else None,
            "max_latency_ticks": float(real.max()) if real.size else None,
            "rounding": rounding,
            "mean_twin_latency_ticks": float(twin.mean()) if twin.size else None,
            # How much later (positive) or earlier the twin applies each action, on average.
            "mean_twin_shift_ticks": float((twin - real).mean()) if real.size else None,
        }


__all__ = ["RecordedEpisode"]
