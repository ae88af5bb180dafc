"""The exact twin of a recorded real-time episode (see :mod:`remoteenv.latency.twin`).

Runs in the agent process. :class:`ExactTwin` drives a real-time sim of the
recording's regime in replay: every reset carries the episode's schedule in
its options (:mod:`remoteenv.wire.run_options.real_time_modes`), and the sim answers each
step at once, its action applied at the substep where real time applied it.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym

from remoteenv.latency.twin.digest import obs_digest
from remoteenv.latency.twin.episode import RecordedEpisode
from remoteenv.wire.run_options.real_time_modes import MAX_REPLAY_RESETS, MAX_REPLAY_STEP_TICKS, replay_options

#: Seeds a reset takes (Gymnasium's: an int >= 0; remoteenv's wire: below 2**64).
_SEEDS = range(0, 2**64)


def check_replayable(episode: RecordedEpisode) -> None:
    """Raise a ValueError saying why ``episode`` cannot be replayed exactly, if
    it cannot (before any sim starts): the recorder named it unreplayable, no
    seed, or more work than a replay may do (:data:`MAX_REPLAY_RESETS` resets to
    reach its start, :data:`MAX_REPLAY_STEP_TICKS` ticks in one step)."""
    if episode.unreplayable:
        raise ValueError(f"this episode cannot be replayed exactly: {episode.unreplayable}")
    if episode.seed is None:
        raise ValueError("this episode's reset had no seed: reset real-time runs with a seed to replay them")
    if isinstance(episode.seed, bool) or not isinstance(episode.seed, int) or episode.seed not in _SEEDS:
        raise ValueError(f"this episode's seed {str(episode.seed)[:30]} is no reset seed (an int in 0..2**64-1)")
    if not 0 <= episode.resets_after_seed <= MAX_REPLAY_RESETS:
        raise ValueError(
            f"this episode starts {str(episode.resets_after_seed)[:30]} unseeded resets after its seed, more than "
            f"the {MAX_REPLAY_RESETS} a replay repeats: reset with a seed every so many episodes to keep them replayable"
        )
    longest = max(episode.ticks_elapsed, default=0)
    if longest > MAX_REPLAY_STEP_TICKS:
        raise ValueError(
            f"a step of this episode lasted {str(longest)[:30]} ticks, more than the {MAX_REPLAY_STEP_TICKS} "
            "one replayed step may run"
        )
    if not episode.action_substeps or len(episode.action_substeps) != episode.steps:
        raise ValueError(f"this episode has {episode.steps} steps but {len(episode.action_substeps)} substeps")


class ExactTwin(gym.Wrapper):
    """A real-time env (``real_time=True`` with the recording's
    ``real_time_mode``) replaying ``episode``: ``reset`` and ``step`` are
    the env's, answered by the sim from the schedule without its clock.

    Reach the episode's start as it was reached: ``reset(seed=episode.seed)``
    then ``episode.resets_after_seed`` unseeded resets (:meth:`reset_to_start`
    does both). Each reset restarts the schedule at the episode's first step.
    The twin's steps match the recording's while the policy repeats its
    actions; a step beyond the recording is refused by the sim.

    Attributes:
        obs_digests, rewards, terminated, truncated: what the twin returned
            since its last reset (fingerprints of the reset's observation and
            of each step's), as :class:`RecordedEpisode` keeps them for the real run.
    """

    def __init__(self, env: gym.Env, episode: RecordedEpisode) -> None:
        check_replayable(episode)
        super().__init__(env)
        handshake = getattr(env.unwrapped, "handshake", None)
        if handshake is not None and (not handshake.real_time or handshake.real_time_mode != episode.mode):
            raise ValueError(
                f"ExactTwin needs a real-time env with real_time_mode={episode.mode!r} (the recording's); "
                "make it with remoteenv.latency.twin.make_twin"
            )
        self.episode = episode
        self.obs_digests: list[str] = []
        self.rewards: list[float] = []
        self.terminated = self.truncated = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(
            seed=seed,
            options=replay_options(options, self.episode.mode, self.episode.action_substeps, self.episode.link_delays),
        )
        self.obs_digests, self.rewards = [obs_digest(obs)], []
        self.terminated = self.truncated = False
        return obs, info

    def reset_to_start(self) -> tuple[Any, dict[str, Any]]:
        """Reset to the recorded episode's start state (its seed, then its unseeded resets)."""
        obs, info = self.reset(seed=self.episode.seed)
        for _ in range(self.episode.resets_after_seed):
            obs, info = self.reset()
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.obs_digests.append(obs_digest(obs))
        self.rewards.append(float(reward))
        self.terminated, self.truncated = bool(terminated), bool(truncated)
        return obs, reward, terminated, truncated, info


__all__ = ["ExactTwin", "check_replayable"]
