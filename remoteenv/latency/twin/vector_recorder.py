"""Recording a real-time vector env's worlds for their twins (see :mod:`remoteenv.latency.twin`). Runs in the agent process."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from remoteenv.agent.launch.restart import INFO_RESTARTED
from remoteenv.latency.twin.recorded_env import RecordedEnv
from remoteenv.latency.twin.recorder import EpisodeLog, RecordedEpisode, check_real_time, real_time_mode


def _world_value(infos: dict[str, Any], key: str, w: int) -> Any:
    """``infos[key][w]`` if world ``w`` reported it (Gymnasium's ``_key`` mask), else None."""
    values = infos.get(key)
    if values is None or not infos.get(f"_{key}", np.ones(w + 1, dtype=bool))[w]:
        return None
    return values[w]


class LatencyRecorderVector(VectorWrapper):
    """:class:`~remoteenv.latency.twin.LatencyRecorder` for a real-time
    :class:`remoteenv.RemoteVectorEnv`: one :class:`~remoteenv.latency.twin.recorder.EpisodeLog` per world.

    Needs the NEXT_STEP autoreset mode (the default): the step after a
    world's episode ends resets that world without a seed, and its next
    episode is recorded with the world's last reset seed and one more
    unseeded reset (``RecordedEpisode.resets_after_seed``), which is how its
    twin reaches the same start state. ``reset(seed=s)`` seeds world ``w``
    with ``s + w`` (a list: one seed per world), as the env does.

    Attributes:
        logs: one :class:`~remoteenv.latency.twin.recorder.EpisodeLog` per world.
    """

    def __init__(self, env: VectorEnv, rounding: str = "nearest") -> None:
        super().__init__(env)
        check_real_time(env, "LatencyRecorderVector")
        mode = AutoresetMode(env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
        if mode != AutoresetMode.NEXT_STEP:
            raise ValueError(f"LatencyRecorderVector needs the NEXT_STEP autoreset mode, got {mode}")
        recorded = RecordedEnv.from_env(env)
        self.logs = [EpisodeLog(rounding, real_time_mode(env), recorded) for _ in range(self.num_envs)]
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
                world_seed = None
            elif isinstance(seed, (int, np.integer)):
                world_seed = int(seed) + w
            else:
                world_seed = seed[w]
            log.start(world_seed, obs[w], {INFO_RESTARTED: _world_value(infos, INFO_RESTARTED, w)}, options)
        self._restarting[:] = False
        return obs, infos

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        try:
            obs, rewards, terminated, truncated, infos = self.env.step(actions)
        except Exception as exc:
            for log in self.logs:
                log.interrupt(f"a vector step raised {type(exc).__name__}")
            raise
        for w, log in enumerate(self.logs):
            restarted = {INFO_RESTARTED: _world_value(infos, INFO_RESTARTED, w)}
            if self._restarting[w]:  # this step reset the world (its action was ignored)
                log.start(None, obs[w], restarted)
                continue
            if restarted[INFO_RESTARTED]:
                log.interrupt("the world's sim was restarted: the episode was lost")
                continue
            keys = ("ticks_elapsed", "latency_ticks", "action_sim_time", "action_substep", "substep", "link_delay_s")
            info = {key: _world_value(infos, key, w) for key in keys}
            if info["ticks_elapsed"] is None:
                raise ValueError(f"world {w}'s step info has no ticks_elapsed: is the vector env real_time=True?")
            log.record_info(info, float(rewards[w]), obs[w])
            if terminated[w] or truncated[w]:
                log.finish(bool(terminated[w]), bool(truncated[w]))
        self._restarting = np.logical_or(terminated, truncated)
        return obs, rewards, terminated, truncated, infos


__all__ = ["LatencyRecorderVector"]
