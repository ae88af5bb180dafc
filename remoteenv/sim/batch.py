"""Batched commands: reset or step several worlds of one sim process per request.

Runs in the sim process (lock-step only). One ``step_batch`` request carries
the actions of the first ``n`` worlds stacked in one array and gets their
results stacked in one reply, so a process hosting K worlds pays one round
trip per vector step instead of K. The wire form of both commands is
specified in :mod:`remoteenv.wire.protocol`. The per-world autoreset
operations (``OP_*``) let the agent's vector env keep Gymnasium's autoreset
semantics without a second round trip.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim.channels import Channel
from remoteenv.sim.checks import RequestError, options_value, require_reset, seed_list, world_list
from remoteenv.sim.lock_step import LockStepper
from remoteenv.wire.actions import check_actions
from remoteenv.wire.batch import columnar_infos, stack
from remoteenv.wire.errors import PROTOCOL, short_repr
from remoteenv.wire.protocol import OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET, OPS


class BatchCommands:
    """The ``reset_batch`` and ``step_batch`` commands over lock-step worlds.

    Actions of Box and Discrete spaces are checked for the whole batch at
    once (bounds of every element, NaN rejected); other spaces one world at
    a time (:func:`remoteenv.wire.actions.check_actions`).

    Args:
        worlds: the lock-step worlds of the process, in world order.
        action_space: the worlds' action space.
        instance: this sim process's index (named in error messages).
    """

    def __init__(self, worlds: Sequence[LockStepper], action_space: spaces.Space, instance: int) -> None:
        self.worlds = worlds
        self.instance = instance
        self._space = action_space
        self._discrete = isinstance(action_space, spaces.Discrete)

    def reset_batch(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        worlds = world_list(msg.get("worlds"), len(self.worlds))
        seeds = seed_list(msg.get("seeds"), len(worlds))
        options = options_value(msg.get("options"))
        obs, infos = [], []
        for w, seed in zip(worlds, seeds):
            o, info = self.worlds[w].reset(seed=seed, options=options)
            obs.append(o)
            infos.append(info)
        return {"obs": stack(obs), "info": columnar_infos(infos)}

    def step_batch(self, msg: dict[str, Any], channel: Channel | None, reply_to: Any) -> dict[str, Any]:
        ops = msg.get("ops")
        num = len(self.worlds)
        if not isinstance(ops, list) or not 0 < len(ops) <= num or not all(type(op) is int and op in OPS for op in ops):
            raise RequestError(PROTOCOL, f"ops must be a list of 1..{num} ints from {OPS}, got {short_repr(ops)}")
        n = len(ops)
        worlds = self.worlds
        for w in range(n):
            if ops[w] != OP_RESET:
                require_reset(worlds[w].has_reset, w, self.instance)
        actions = check_actions(self._space, msg.get("actions"), n)
        if isinstance(actions, np.ndarray) and self._discrete:
            actions = actions.tolist()
        obs: list[Any] = [None] * n
        infos: list[Any] = [None] * n
        reward = np.zeros(n, dtype=np.float64)
        terminated = np.zeros(n, dtype=np.bool_)
        truncated = np.zeros(n, dtype=np.bool_)
        final: list[Any] = []
        final_types: list[Any] = []
        for w in range(n):
            op = ops[w]
            world = worlds[w]
            if op == OP_RESET:
                obs[w], infos[w] = world.reset(seed=None, options=None)
                continue
            r = world.step(actions[w])
            reward[w] = r["reward"]
            terminated[w] = r["terminated"]
            truncated[w] = r["truncated"]
            if op == OP_STEP_RESET or (op == OP_STEP_AUTORESET and (r["terminated"] or r["truncated"])):
                final.append([w, r["obs"], r["info"]])
                final_types.append(r.get("types", {}).get("info"))
                obs[w], infos[w] = world.reset(seed=None, options=None)
            else:
                obs[w], infos[w] = r["obs"], r["info"]
        # Short vectors go as msgpack lists: cheaper than arrays to encode and decode.
        reply = {
            "obs": stack(obs),
            "reward": reward.tolist(),
            "terminated": terminated.tolist(),
            "truncated": truncated.tolist(),
            "info": columnar_infos(infos),
            "final": final,
        }
        if any(final_types):
            reply["final_types"] = final_types
        return reply


__all__ = ["BatchCommands"]
