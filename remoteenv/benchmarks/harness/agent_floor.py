"""remoteenv's sims under a bare agent end: how much of a vector step is the agent's.

Benchmarks only (``bench --train-loop``'s ``agent-floor`` contender). Runs in
the agent process. :class:`AgentFloorVectorEnv` is remoteenv's default
vector env of Reacher worlds (same layout, sims, torch threads and
placement), whose steps between episode ends bypass its agent end: the
actions go straight into each sim's shared region and are posted on its
doorbell (:mod:`remoteenv.wire.shared_memory.doorbell`, with the think time
remoteenv's agent end tells its sims), the agent blocks at once for each
reply (no hot wait), and the observations, rewards and flags are copied out
of the regions. No action check, no reply checks beyond the
doorbell's sequence word, no infos, no latency bookkeeping, no failure
handling beyond a sim's end of file or a frame that is not a wake-up. The
time limit is kept: a step that resets a world (the one after an episode
end, with Gymnasium's next-step autoreset) goes through the vector env
itself, as do the steps before every region is attached.

The sims are remoteenv's, unchanged. So this contender against
``remoteenv`` measures what remoteenv's agent end costs, and
``process-floor`` (:mod:`remoteenv.benchmarks.harness.process_floor`, a
bare child process under the same bare agent) against this one what the
sims' end costs: the two ends of the lane, each in the loop users run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from remoteenv.agent.connection.pipe_connection import PipeConnection
from remoteenv.wire import protocol
from remoteenv.wire.protocol import OP_STEP

#: What this harness steps: remoteenv's Reacher, as the ``remoteenv`` contender does.
REMOTE_ID = "remoteenv/Reacher-v0"


class AgentFloorVectorEnv:
    """``num_envs`` Reacher worlds of remoteenv's default vector env, stepped
    through a bare agent end between episode ends (see the module).

    ``reset``, ``step`` and ``close`` as a Gymnasium vector env's, without
    infos from the bare steps.
    """

    def __init__(self, num_envs: int) -> None:
        import gymnasium as gym

        self.env = gym.make_vec(REMOTE_ID, num_envs, vectorization_mode="vector_entry_point")
        self._vector: Any = self.env.unwrapped
        self.num_envs = num_envs
        self.single_observation_space = self.env.single_observation_space
        self.single_action_space = self.env.single_action_space
        #: Per sim: its worlds ``(first, end)``, connection, region arrays and doorbell (once attached).
        self._lanes: list[tuple[int, int, PipeConnection, Any, Any]] | None = None
        #: Vector steps taken by the bare agent end and by the vector env.
        self.bare_steps = self.full_steps = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        return self.env.reset(seed=seed, options=options)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        episodes = self._vector._episodes
        lanes = self._lanes if self._lanes is not None else self._attach()
        if lanes is None or episodes.needs_reset.any():
            self.full_steps += 1
            return self.env.step(actions)
        self.bare_steps += 1
        think_s = episodes.think_s()  # what remoteenv's agent end tells the sims
        actions = np.asarray(actions, dtype=np.float32)
        posted = []
        for lo, hi, conn, arrays, bell in lanes:
            arrays.actions[: hi - lo] = actions[lo:hi]
            arrays.ops[: hi - lo] = OP_STEP
            posted.append(conn.post(bell, hi - lo, False, think_s))
        for (_, _, conn, _, bell), seq in zip(lanes, posted):
            while not bell.answered(seq):
                if bell.agent_sleeps(seq):
                    try:
                        conn._read(True)  # a wake-up frame, or SO_RCVTIMEO's liveness interval
                    finally:
                        bell.agent_wakes()
                    _drop_wakeups(conn, seq)
            conn._unanswered.pop(seq, None)
            conn._watch = None
        obs = np.concatenate([arrays.obs[: hi - lo] for lo, hi, _, arrays, _ in lanes])
        reward = np.concatenate([arrays.reward[: hi - lo] for lo, hi, _, arrays, _ in lanes])
        terminated = (
            np.concatenate([arrays.terminated[: hi - lo].view(np.uint8) for lo, hi, _, arrays, _ in lanes]) != 0
        )
        elapsed = episodes.elapsed + 1
        truncated = elapsed >= episodes.max_episode_steps if episodes.max_episode_steps else np.zeros_like(terminated)
        episodes.elapsed, episodes.needs_reset, episodes.obs = elapsed, terminated | truncated, obs
        episodes.returned()
        return obs, reward, terminated, truncated, {}

    def _attach(self) -> list[tuple[int, int, PipeConnection, Any, Any]] | None:
        """Every sim's region and doorbell, once the vector env has attached them all (else None)."""
        shared = self._vector._requests.lanes
        conns = self._vector._session.conns
        out = []
        for p, (lo, hi) in enumerate(self._vector.slices):
            known, bell = shared._lanes.get(p), shared._bells.get(p)
            if known is None or known[1] is None or bell is None or not isinstance(conns[p], PipeConnection):
                return None
            out.append((lo, hi, conns[p], known[1], bell))
        self._lanes = out
        return out

    def close(self) -> None:
        self.env.close()


def _drop_wakeups(conn: PipeConnection, seq: int) -> None:
    """Drop the sim's wake-up frames (for ``seq`` or an earlier request); anything else is an error."""
    while conn._frames:
        reply = protocol.unpack(conn._frames.popleft())
        got = reply.get("seq") if isinstance(reply, dict) else None
        if not (type(got) is int and got <= seq and reply.get("region") is True and reply.get("ok") is True):
            raise RuntimeError(
                f"agent-floor: sim instance {conn.instance} sent {repr(reply)[:200]} where only a wake-up "
                f"for request {seq} may come; this harness handles plain steps only"
            )


__all__ = ["AgentFloorVectorEnv"]
