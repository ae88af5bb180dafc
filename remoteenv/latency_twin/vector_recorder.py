"""Recording a real-time vector env's worlds for their twins (see :mod:`remoteenv.latency_twin`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from remoteenv.latency_twin.recorder import EpisodeLog, RecordedEpisode, check_real_time


def _world_value(infos: dict[str, Any], key: str, w: int) -> Any:
    """``infos[key][w]`` if world ``w`` reported it (Gymnasium's ``_key`` mask), else None."""
    values = infos.get(key)
    if values is None or not infos.get(f"_{key}", np.ones(w + 1, dtype=bool))[w]:
        return None
    return values[w]


class LatencyRecorderVector(VectorWrapper):
    """:class:`~remoteenv.latency_twin.LatencyRecorder` for a real-time
    :class:`remoteenv.RemoteVectorEnv`: one :class:`~remoteenv.latency_twin.recorder.EpisodeLog` per world.

    Needs the NEXT_STEP autoreset mode (the default): the step after a
    world's episode ends resets that world without a seed, and its next
    episode is recorded with the world's last reset seed and one more
    unseeded reset (``RecordedEpisode.resets_after_seed``), which is how its
    twin reaches the same start state. ``reset(seed=s)`` seeds world ``w``
    with ``s + w`` (a list: one seed per world), as the env does.

    Attributes:
        logs: one :class:`~remoteenv.latency_twin.recorder.EpisodeLog` per world.
    """

    def __init__(self, env: VectorEnv, rounding: str = "nearest") -> None:
        super().__init__(env)
        check_real_time(env, "LatencyRecorderVector")
        mode = AutoresetMode(env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
        if mode != AutoresetMode.NEXT_STEP:
            raise ValueError(f"LatencyRecorderVector needs the NEXT_STEP autoreset mode, got {mode}")
        self.logs = [EpisodeLog(rounding) for _ in range(self.num_envs)]
        self._restarting = np.zeros(self.num_envs, dtype=bool)

    @property
    def episodes(self) -> list[list[RecordedEpisode]]:
        """Per world, its recorded episodes, oldest first."""
        return [log.episodes for log in self.logs]

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        if options and "reset_mask" in options:
            raise ValueError("LatencyRecorderVector records NEXT_STEP autoresets; reset_mask is not supported")
        obs, infos = self.env.reset(seed=seed, options=options)  # type: ignore[arg-type]  # RemoteVectorEnv takes lists
        for w, log in enumerate(self.logs):
            if seed is None:
                log.start(None)
            elif isinstance(seed, (int, np.integer)):
                log.start(int(seed) + w)
            else:
                log.start(seed[w])
        self._restarting[:] = False
        return obs, infos

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        for w, log in enumerate(self.logs):
            if self._restarting[w]:  # this step reset the world (its action was ignored)
                log.start(None)
                continue
            ticks = _world_value(infos, "ticks_elapsed", w)
            if ticks is None:
                raise ValueError(f"world {w}'s step info has no ticks_elapsed: is the vector env real_time=True?")
            latency = _world_value(infos, "latency_ticks", w)
            applied = _world_value(infos, "action_sim_time", w) is not None and latency is not None
            applied = applied and math.isfinite(float(latency))
            log.record(int(ticks), float(latency) if applied else None, float(rewards[w]))
            if terminated[w] or truncated[w]:
                log.finish(bool(terminated[w]), bool(truncated[w]))
        self._restarting = np.logical_or(terminated, truncated)
        return obs, rewards, terminated, truncated, infos


__all__ = ["LatencyRecorderVector"]
