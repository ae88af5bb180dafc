"""Batched commands: reset or step several worlds of one sim process per request.

Runs in the sim process (lock-step only). One ``step_batch`` request carries
the actions of several worlds stacked in one array and gets their results
stacked in one reply, so a process hosting K worlds pays one round trip per
vector step instead of K. The wire form of both commands is specified in
:mod:`remoteenv.wire.protocol`. The per-world autoreset operations (``OP_*``)
let the agent's vector env keep Gymnasium's autoreset semantics without a
second round trip.

Without action or observation delays the stepped worlds advance together
(:class:`~remoteenv.sim.stepping.batch_step.WorldsStepper`: the scene's batched
hooks, physics on threads); with one, or for worlds that cannot be stepped
together, each world steps through its :class:`LockStepper`. Both give the
same results.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.stepping.autoreset_reply import autoreset_reply
from remoteenv.sim.stepping.batch_step import WorldsStepper, steps_together
from remoteenv.sim.stepping.lock_step import LockStepper
from remoteenv.sim.stepping.plain_region_step import PlainRegionStep, batch_infos, plain_step_reply, region_reply
from remoteenv.sim.transport.channels import Channel
from remoteenv.sim.transport.checks import RequestError, options_value, require_reset, seed_list, world_list
from remoteenv.sim.transport.shared_lane_server import SharedLane
from remoteenv.wire.codec.scalar_types import describe_scalars
from remoteenv.wire.messages.action_rules import BatchCheck
from remoteenv.wire.messages.batch_encoding import columnar_infos, stack
from remoteenv.wire.protocol import OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET, OPS
from remoteenv.wire.wire_errors import PROTOCOL, STATE, short_repr


class BatchCommands:
    """The ``reset_batch`` and ``step_batch`` commands over lock-step worlds.

    Actions of Box and Discrete spaces are checked for the whole batch at
    once (bounds of every element, NaN rejected); other spaces one world at
    a time (:class:`remoteenv.wire.messages.action_rules.BatchCheck`).

    Args:
        worlds: the lock-step worlds of the process, in world order.
        action_space: the worlds' action space.
        instance: this sim process's index (named in error messages).
        threads: physics threads of the batched path (default:
            :func:`~remoteenv.sim.stepping.batch_physics.default_threads`).
    """

    def __init__(
        self, worlds: Sequence[LockStepper], action_space: spaces.Space, instance: int, threads: int | None = None
    ) -> None:
        self.worlds = worlds
        self.instance = instance
        self._check = BatchCheck(action_space)
        self._discrete = isinstance(action_space, spaces.Discrete)
        envs = [w.env for w in worlds]
        together = all(w.delays.is_zero for w in worlds) and steps_together(envs)
        self.stepper = WorldsStepper(envs, threads) if together else None
        #: The local pipe's shared-memory region (``shared_batch``), for worlds stepped together.
        self.lane = SharedLane(action_space, envs[0].observation_space, len(worlds)) if together else None
        #: Every world has been reset (then no step needs the per-world check).
        self._all_reset = False
        #: Plain steps of every world posted in the region, served from the sim's wait (None: no region here).
        self.plain_region = (
            PlainRegionStep(self.lane, self.stepper, self._check, lambda: self._all_reset)
            if self.lane is not None and self.stepper is not None
            else None
        )

    def close(self) -> None:
        """Stop the physics threads; unmap the shared region."""
        if self.stepper is not None:
            self.stepper.close()
        if self.lane is not None:
            self.lane.close()

    def physics(self) -> dict[str, Any]:
        """How the process steps its worlds' physics, for the handshake's metadata:
        ``physics_threads`` (threads, the caller's included) and ``stacked_hooks``
        (every world in one ``mujoco.batch`` with the scene's stacked hooks: the
        process's Python runs once per tick, not once per world)."""
        stepper = self.stepper
        if stepper is None:
            return {"physics_threads": 1, "stacked_hooks": False}
        return {"physics_threads": stepper.threads, "stacked_hooks": stepper.batched is not None}

    def handlers(self) -> dict[str, Any]:
        """The commands this object answers (``shared_batch`` when the worlds' spaces fit a region)."""
        out: dict[str, Any] = {"reset_batch": self.reset_batch, "step_batch": self.step_batch}
        if self.lane is not None and self.lane.offered:
            out["shared_batch"] = self.lane.attach
        return out

    def reset_batch(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        worlds = world_list(msg.get("worlds"), len(self.worlds))
        seeds = seed_list(msg.get("seeds"), len(worlds))
        options = options_value(msg.get("options"))
        obs, infos = self._start(worlds, seeds, options)
        return {"obs": _stacked(obs), "info": columnar_infos(infos)}

    def _start(
        self, worlds: list[int], seeds: list[int | None], options: dict[str, Any] | None
    ) -> tuple[Any, list[dict[str, Any]]]:
        """Start an episode in each of ``worlds`` (``seeds[j]`` for ``worlds[j]``;
        None continues its RNG's stream): their obs (a list, or an array of
        rows) and infos, in order. Together in one call when the scene has its
        own ``reset_models`` (:meth:`WorldsStepper.reset`), else world by world."""
        stepper = self.stepper
        if stepper is None or not stepper.resets_together:
            started = [self.worlds[w].reset(seed=seed, options=options) for w, seed in zip(worlds, seeds)]
            return [o for o, _ in started], [info for _, info in started]
        for w, seed in zip(worlds, seeds):
            if seed is not None:
                self.worlds[w].env.seed_rng(seed)
        obs, infos, times = stepper.reset(worlds, options)
        for j, w in enumerate(worlds):
            self.worlds[w].started(obs[j], seeds[j], float(times[j]))
        return obs, infos

    def _start_at(self, worlds: list[int], starts: list[int]) -> tuple[Any, list[dict[str, Any]]]:
        """Start an episode, unseeded, in the worlds at request positions ``starts`` (``worlds[j]``): see :meth:`_start`."""
        return self._start([worlds[j] for j in starts], [None] * len(starts), None)

    def step_batch(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any] | None:
        """A ``step_batch``: its ops, worlds and actions in the message, or with
        ``"region": true`` posted in the region (see :meth:`from_region`)."""
        if msg.get("region") is True:
            return self.from_region(msg, channel)
        num = len(self.worlds)
        ops = msg.get("ops")
        if not isinstance(ops, list) or not 0 < len(ops) <= num or not all(type(op) is int and op in OPS for op in ops):
            raise RequestError(PROTOCOL, f"ops must be a list of 1..{num} ints from {OPS}, got {short_repr(ops)}")
        n = len(ops)
        worlds = self._request_worlds(msg.get("worlds"), n)
        self._require_reset(ops, worlds)
        shared = msg.get("shared") is True
        if shared:
            if self.lane is None or msg.get("worlds") is not None:
                raise RequestError(PROTOCOL, "a 'shared' step_batch needs shared_batch first and no 'worlds'")
            actions = self._check(self.lane.actions(n, channel), n)
        else:
            actions = self._check(msg.get("actions"), n)
        reply = self._step(ops, worlds, actions, shared=shared)
        assert reply is not None
        return reply

    def from_region(self, msg: dict[str, Any], channel: Channel | None) -> dict[str, Any] | None:
        """The ``step_batch`` posted in the region as request ``msg["seq"]`` (its
        ``{"region": true}`` frame, or found there by the pipe's watch): answered
        in the region where it fits (no reply here, or ``{"region": true}`` to
        wake the agent), else on the pipe as usual. Nothing for a request
        served already (its frame came after the watch had found it)."""
        lane = self.lane
        if lane is None:
            raise RequestError(STATE, "a region step_batch needs the region of shared_batch")
        taken = lane.take(msg["seq"], channel)
        if taken is None:
            return None
        ops, named, actions = taken
        n = len(ops)
        worlds = list(range(n)) if named is None else self._request_worlds(named, n)
        self._require_reset(ops, worlds)
        return self._step(ops, worlds, self._check(actions, n), shared=True, seq=msg["seq"])

    def _require_reset(self, ops: list[int], worlds: list[int]) -> None:
        """A ``state`` error for a world stepped before its first reset (once every
        world has been reset, nothing to look at)."""
        if self._all_reset:
            return
        for j, w in enumerate(worlds):
            if ops[j] != OP_RESET:
                require_reset(self.worlds[w].has_reset, w, self.instance)
        self._all_reset = all(w.has_reset for w in self.worlds)

    def _step(
        self, ops: list[int], worlds: list[int], actions: Any, *, shared: bool, seq: int = 0
    ) -> dict[str, Any] | None:
        """One tick of positions ``0 .. n-1`` (``ops[j]`` for world ``worlds[j]``,
        checked); the reply's fields (None: answered in the region, ``seq``)."""
        n = len(ops)
        all_step = OP_RESET not in ops
        # Actions sent as a list reach the hooks as sent (e.g. floats, not float32): per world.
        if (
            self.stepper is not None
            and isinstance(actions, np.ndarray)
            and (all_step or any(op != OP_RESET for op in ops))
        ):
            if all_step:
                stepped, picked, stepped_worlds = None, actions, worlds
            else:
                stepped = [j for j in range(n) if ops[j] != OP_RESET]
                picked = actions[stepped]
                stepped_worlds = [worlds[j] for j in stepped]
            # A plain step answered through the region renders camera images straight into it.
            lane = self.lane
            rows = lane.obs_rows(n) if all_step and lane is not None and (seq or shared) else None
            heads_up = (lambda: lane.physics_done(seq)) if seq and lane is not None else None
            batch = self.stepper.step(stepped_worlds, picked, rows, heads_up)
            resets = not all_step or OP_STEP_RESET in ops or (OP_STEP_AUTORESET in ops and batch.terminated.any())
            if not resets:
                if seq and lane is not None:
                    return region_reply(lane, seq, batch)
                if shared and lane is not None:
                    reply = lane.reply(batch, batch_infos(batch))
                    if reply is not None:
                        return reply
                return plain_step_reply(batch)  # the scene's arrays as they are
            positions = stepped if stepped is not None else list(range(n))
            # Some worlds start an episode: the reply from the arrays where they allow it.
            reply = autoreset_reply(batch, ops, positions, lambda starts: self._start_at(worlds, starts))
            if reply is not None:
                return reply
            results = _per_world_results(batch, positions, n)
        else:
            if isinstance(actions, np.ndarray) and self._discrete:
                actions = actions.tolist()
            results = [None if ops[j] == OP_RESET else self.worlds[worlds[j]].step(actions[j]) for j in range(n)]
        return self._reply(ops, worlds, results)

    # ------------------------------------------------------------ helpers

    def _request_worlds(self, worlds: Any, n: int) -> list[int]:
        """The worlds a ``step_batch`` addresses: ``worlds`` (distinct, one per op) or ``0 .. n-1``."""
        if worlds is None:
            return list(range(n))
        checked = world_list(worlds, len(self.worlds))
        if len(checked) != n or len(set(checked)) != n:
            raise RequestError(PROTOCOL, f"worlds must list {n} distinct worlds, one per op, got {short_repr(worlds)}")
        return checked

    def _reply(self, ops: list[int], worlds: list[int], results: list[dict[str, Any] | None]) -> dict[str, Any]:
        """The reply from each request position's step result (None: the op was a reset)."""
        n = len(ops)
        obs: list[Any] = [None] * n
        infos: list[Any] = [None] * n
        reward = np.zeros(n, dtype=np.float64)
        terminated = np.zeros(n, dtype=np.bool_)
        truncated = np.zeros(n, dtype=np.bool_)
        final: list[Any] = []
        final_types: list[Any] = []
        starts: list[int] = []  # the positions whose world starts an episode
        for j, r in enumerate(results):
            op = ops[j]
            if r is None:
                starts.append(j)
                continue
            reward[j] = r["reward"]
            terminated[j] = r["terminated"]
            truncated[j] = r["truncated"]
            if op == OP_STEP_RESET or (op == OP_STEP_AUTORESET and (r["terminated"] or r["truncated"])):
                final.append([j, r["obs"], r["info"]])
                final_types.append(r.get("types", {}).get("info"))
                starts.append(j)
            else:
                obs[j], infos[j] = r["obs"], r["info"]
        if starts:
            started, started_infos = self._start_at(worlds, starts)
            if len(starts) == n and isinstance(started, np.ndarray):
                obs = started  # type: ignore[assignment]
            else:
                for i, j in enumerate(starts):
                    obs[j] = started[i]
            for i, j in enumerate(starts):
                infos[j] = started_infos[i]
        # Short vectors go as msgpack lists: cheaper than arrays to encode and decode.
        reply: dict[str, Any] = {
            "obs": _stacked(obs),
            "reward": reward.tolist(),
            "terminated": terminated.tolist(),
            "truncated": truncated.tolist(),
            "info": columnar_infos(infos),
            "final": final,
        }
        if any(final_types):
            reply["final_types"] = final_types
        return reply


def _stacked(obs: Any) -> Any:
    """Observations for the wire: an array of rows as it is, a list stacked where it can be."""
    return obs if isinstance(obs, np.ndarray) else stack(obs)


def _per_world_results(batch: BatchResult, stepped: list[int], n: int) -> list[dict[str, Any] | None]:
    """``batch`` (results of request positions ``stepped``) as per-position step results."""
    results: list[dict[str, Any] | None] = [None] * n
    for i, j in enumerate(stepped):
        results[j] = describe_scalars(
            {
                "obs": batch.world_obs(i),
                "reward": batch.reward[i],
                "terminated": bool(batch.terminated[i]),
                "truncated": False,
                "info": batch.world_info(i),
            }
        )
    return results


__all__ = ["BatchCommands", "plain_step_reply"]
