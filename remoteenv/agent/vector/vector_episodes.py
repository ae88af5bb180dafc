"""The episodes of a vector env's worlds: reset, step and EnvPool's send/recv
over their sims, with the autoreset bookkeeping between calls.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv` holds one and
keeps Gymnasium's vector API on top of it). :class:`VectorEpisodes` checks
the actions, plans each world's op (:mod:`~remoteenv.agent.vector.autoreset`),
sends the requests of a call (:mod:`~remoteenv.agent.vector.vector_requests`,
:mod:`~remoteenv.agent.vector.vector_async`), assembles the replies
(:mod:`~remoteenv.agent.vector.vector_results`) and keeps what the next call
needs: each world's step count, which worlds the next step resets, the last
obs batch and the step in flight. Infos are merged with the env's
``_add_info`` (Gymnasium's), passed in by each call so this object holds no
reference back to the env.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space, iterate

from remoteenv.agent.errors import StateError
from remoteenv.agent.launch.restart import restarted_info
from remoteenv.agent.session.reset_args import split_reset_mask, world_seeds
from remoteenv.agent.session.sim_session import SimSession
from remoteenv.agent.vector.autoreset import after_reset, after_step, plan_ops
from remoteenv.agent.vector.lean_step import LeanStep
from remoteenv.agent.vector.vector_async import AsyncWorlds, assemble_chunks
from remoteenv.agent.vector.vector_layout import check_sims
from remoteenv.agent.vector.vector_requests import VectorRequests
from remoteenv.agent.vector.vector_results import ObsBatch, assemble
from remoteenv.wire.messages.action_rules import BatchCheck, check_actions
from remoteenv.wire.messages.batch_encoding import AddInfo, merge_infos
from remoteenv.wire.shared_memory.hot_wait import usable_cpus

#: What a vector step returns: ``(obs, rewards, terminated, truncated, infos)``.
StepResult = tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]


class VectorEpisodes:
    """The worlds ``slices`` of ``session``'s sims, stepped as one batch.

    Args:
        session: the open session; its sims are checked against ``slices``
            first (:func:`~remoteenv.agent.vector.vector_layout.check_sims`).
        slices: ``(first, end)`` world indices of each sim.
        autoreset_mode, max_episode_steps: as the env was given them.
        real_time: the sims run on a paced clock (one world each).
        batch_size: worlds :meth:`recv` returns.
    """

    def __init__(
        self,
        session: SimSession,
        slices: Sequence[tuple[int, int]],
        autoreset_mode: AutoresetMode,
        max_episode_steps: int | None,
        real_time: bool,
        batch_size: int,
    ) -> None:
        self.slices = list(slices)
        width = max(hi - lo for lo, hi in self.slices)
        check_sims(session.handshakes, self.slices, batches=not (real_time or width == 1))
        self.session = session
        self.num_envs = n = self.slices[-1][1]
        #: One world's spaces (the first sim's handshake's).
        self.observation_space = observation_space = session.handshake.observation_space
        self.action_space = action_space = session.handshake.action_space
        self.batched_action_space = batch_space(action_space, n)
        self.mode, self.max_episode_steps = autoreset_mode, max_episode_steps
        self.real_time, self.batch_size = real_time, batch_size
        self.obs_batch = ObsBatch(observation_space, n)
        self._box_act = isinstance(action_space, gym.spaces.Box)
        self._batch_check = BatchCheck(action_space)
        same_step = autoreset_mode == AutoresetMode.SAME_STEP
        self.requests = VectorRequests(session, self.slices, real_time=real_time, same_step=same_step)
        self.async_worlds = AsyncWorlds(session, self.slices, n, self.requests.lanes)
        #: Plain steps through the region of the only sim process, when there is one such (else None).
        self._lean = (
            LeanStep(session, self.requests.lanes, n, observation_space.dtype)
            if len(self.slices) == 1 and not self.requests.plain_steps and self.obs_batch.box
            else None
        )
        #: The step in flight: its ops, actions, ``{process: seq}``, start time, and whether :attr:`_lean` posted it.
        self._pending_step: tuple[np.ndarray, Any, dict[int, int], float, bool] | None = None
        #: Steps of each world's current episode.
        self.elapsed = np.zeros(n, dtype=np.int64)
        #: Worlds whose episode ended and that the next step resets.
        self.needs_reset = np.zeros(n, dtype=np.bool_)
        self.has_reset = False
        #: The last obs batch (internal form, see :class:`ObsBatch`).
        self.obs: Any = None
        #: ``perf_counter()`` when the last reset or step returned to the caller (None: in flight or never).
        self._returned_at: float | None = None
        #: Whether the sims are told the caller's think time: when this machine's sims of the env
        #: take every CPU, a sim waiting hot through it takes the caller's CPU (docs/performance.md).
        self._tell_think = session.local_sims >= usable_cpus()

    def check_idle(self) -> None:
        """StateError unless nothing is in flight (what ``reset`` needs)."""
        if self._pending_step is not None or self.async_worlds.busy:
            raise StateError("reset() while steps are in flight: step_wait() or recv() them first")

    def reset(
        self, seed: int | Sequence[int | None] | None, options: dict[str, Any] | None, add_info: AddInfo
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every world, or those of ``options["reset_mask"]`` (see :meth:`remoteenv.RemoteVectorEnv.reset`)."""
        self.check_idle()
        seeds = world_seeds(seed, self.num_envs)
        options, mask = split_reset_mask(options, self.num_envs, first_reset=not self.has_reset)
        worlds_of = {}
        for p, (lo, hi) in enumerate(self.slices):
            worlds = [i - lo for i in range(lo, hi) if mask[i]]
            if worlds:
                worlds_of[p] = worlds
        replies, restarted = self.requests.reset(worlds_of, seeds, options)
        obs = self.obs_batch.fresh(self.obs, full=bool(mask.all()))
        infos: dict[str, Any] = {}
        for p, worlds in worlds_of.items():
            idx = np.asarray(worlds, dtype=np.intp) + self.slices[p][0]
            self.obs_batch.put(obs, idx, replies[p]["obs"])
            merge_infos(infos, replies[p]["info"], idx, self.num_envs, add_info)
            if p in restarted:
                for i in idx:
                    add_info(infos, restarted_info(restarted[p], self.session.restarts.count), int(i))
        after_reset(mask, self.elapsed, self.needs_reset)
        self.has_reset = True
        self.obs = obs
        self.returned()
        return self.obs_batch.for_gym(obs), infos

    def start_step(self, actions: Any) -> None:
        """Send every world's action (or autoreset) and return at once."""
        if not self.has_reset or self.session.closed:
            raise StateError("step() before reset() or after close(): reset() an open RemoteVectorEnv first")
        if self._pending_step is not None or self.async_worlds.busy:
            raise StateError("a step is in flight: call step_wait() (or recv() what send() sent) first")
        think_s = self.think_s()
        acts = self.check_actions(actions, self.num_envs)
        ops = plan_ops(self.mode, self.needs_reset, self.elapsed, self.max_episode_steps)
        started = time.perf_counter()
        lean = self._lean
        seq = None if lean is None else lean.post(ops, acts, think_s)
        pending = {0: seq} if seq is not None else self.requests.start_step(ops, acts, think_s)
        self._pending_step = (ops, acts, pending, started, seq is not None)

    def finish_step(self, add_info: AddInfo) -> tuple[StepResult, float]:
        """The results of the step :meth:`start_step` sent, and its wall round trip (s)."""
        if self._pending_step is None:
            raise StateError("step_wait() without step_async(): nothing is in flight")
        ops, acts, pending, started, lean = self._pending_step
        self._pending_step = None
        out = self._lean.finish(pending[0]) if lean and self._lean is not None else None
        if out is None:
            results = self.requests.finish_step(pending, ops, acts, self.obs, self.obs_batch)
            out = assemble(results, self.slices, self.obs_batch, add_info)
        round_trip = time.perf_counter() - started
        obs, rewards, terminated, truncated, infos = out
        mode, limit = self.mode, self.max_episode_steps
        truncated, self.elapsed, self.needs_reset = after_step(mode, ops, terminated, truncated, self.elapsed, limit)
        self.obs = obs
        self.returned()
        return (self.obs_batch.for_gym(obs), rewards, terminated, truncated, infos), round_trip

    def returned(self) -> None:
        """A reset or step returns to the caller now: its think time starts."""
        self._returned_at = time.perf_counter()

    def think_s(self) -> float:
        """The caller's think time (its policy, its update) before the step starting
        now, in seconds: since the last reset or step returned, when the sims are
        told it (they do not wait hot through a long one), else 0. Counted once."""
        returned_at, self._returned_at = self._returned_at, None
        return time.perf_counter() - returned_at if returned_at is not None and self._tell_think else 0.0

    def send(self, actions: Any, env_ids: Any = None) -> None:
        """EnvPool's send (see :meth:`remoteenv.RemoteVectorEnv.send`)."""
        if not self.has_reset or self.session.closed:
            raise StateError("send() before reset() or after close(): reset() an open RemoteVectorEnv first")
        if self.real_time or not all(hs.offers("step_batch") for hs in self.session.handshakes):
            raise StateError("send()/recv() need lock-step sims that answer step_batch; step with step()")
        if self._pending_step is not None:
            raise StateError("a step is in flight: call step_wait() first")
        ids = np.arange(self.num_envs) if env_ids is None else np.asarray(env_ids, dtype=np.intp).reshape(-1)
        if len(ids) == 0 or ids.min() < 0 or ids.max() >= self.num_envs or len(np.unique(ids)) != len(ids):
            raise ValueError(f"env_ids must be distinct world indices in [0, {self.num_envs}), got {ids[:8]!r}")
        acts = self.check_actions(actions, len(ids))
        ops = plan_ops(self.mode, self.needs_reset[ids], self.elapsed[ids], self.max_episode_steps)
        self.async_worlds.send(ids, ops, acts)

    def recv(self, add_info: AddInfo) -> StepResult:
        """EnvPool's recv: the first ``batch_size`` worlds to finish (see :meth:`remoteenv.RemoteVectorEnv.recv`)."""
        chunks = self.async_worlds.recv(self.batch_size)
        ids, ops, obs, rewards, terminated, truncated, infos = assemble_chunks(
            chunks, ObsBatch(self.observation_space, self.batch_size), add_info
        )
        truncated, elapsed, needs_reset = after_step(
            self.mode, ops, terminated, truncated, self.elapsed[ids], self.max_episode_steps
        )
        self.elapsed[ids], self.needs_reset[ids] = elapsed, needs_reset
        self.obs_batch.put(self.obs, ids, obs)
        out_obs = ObsBatch(self.observation_space, self.batch_size).for_gym(obs)
        return out_obs, rewards, terminated, truncated, infos

    def check_actions(self, actions: Any, n: int) -> Any:
        """``n`` actions in wire form, indexable by world; ValueError names the world."""
        space = self.action_space
        if self._box_act:
            return self._batch_check(np.asarray(actions), n)
        if isinstance(space, gym.spaces.Discrete) and isinstance(actions, np.ndarray) and actions.dtype.kind in "iu":
            return check_actions(space, actions, n)  # one vectorised range check
        batched = self.batched_action_space if n == self.num_envs else batch_space(space, n)
        checked = check_actions(space, list(iterate(batched, actions)), n)
        if isinstance(space, gym.spaces.Discrete):
            return np.asarray(checked, dtype=np.int64)
        return checked


__all__ = ["StepResult", "VectorEpisodes"]
