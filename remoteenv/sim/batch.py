"""Batched commands: reset or step several worlds of one sim process per request.

Runs in the sim process. One ``step_batch`` request carries the actions of the
first ``n`` worlds stacked in one array and gets their results stacked in one
reply, so a process hosting K worlds pays one round trip per vector step
instead of K. The wire form of both commands is specified in
:mod:`remoteenv.protocol`. The per-world autoreset operations (``OP_*``) let
the agent's vector env keep Gymnasium's autoreset semantics without a second
round trip.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from gymnasium import spaces

from remoteenv.wire.actions import check_actions
from remoteenv.wire.batch import columnar_infos
from remoteenv.wire.errors import InvalidAction
from remoteenv.wire.batch import stack as _stack
from remoteenv.wire.protocol import OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET, OPS

if TYPE_CHECKING:
    from remoteenv.sim.server import RemoteControlledAgent

class BatchCommands:
    """The ``reset_batch`` and ``step_batch`` commands of one server.

    Actions of Box and Discrete spaces are checked for the whole batch at
    once (bounds of every element, NaN rejected); other spaces fall back to
    the server's per-world check.
    """

    def __init__(self, server: "RemoteControlledAgent") -> None:
        self.server = server
        space = server.envs[0].action_space
        self._space = space
        self._box = isinstance(space, spaces.Box)
        self._discrete = isinstance(space, spaces.Discrete)

    def handlers(self) -> dict[str, Callable[[dict[str, Any]], dict[str, Any]]]:
        return {"reset_batch": self.reset_batch, "step_batch": self.step_batch}

    # ------------------------------------------------------------ commands

    def reset_batch(self, msg: dict[str, Any]) -> dict[str, Any]:
        from remoteenv.sim.server import RequestError

        server = self.server
        worlds = msg.get("worlds")
        num = len(server.envs)
        if (
            not isinstance(worlds, list) or not worlds
            or not all(isinstance(w, int) and not isinstance(w, bool) and 0 <= w < num for w in worlds)
        ):
            raise RequestError("protocol", f"worlds must be a non-empty list of ints in [0, {num}), got {worlds!r:.200}")
        seeds = msg.get("seeds")
        if seeds is None:
            seeds = [None] * len(worlds)
        if not isinstance(seeds, list) or len(seeds) != len(worlds) or not all(
            s is None or (isinstance(s, int) and not isinstance(s, bool) and s >= 0) for s in seeds
        ):
            raise RequestError("protocol", "seeds must be nil or a list (one per world) of non-negative ints or nil")
        options = msg.get("options")
        if options is not None and not isinstance(options, dict):
            raise RequestError("protocol", f"options must be a map or nil, got {type(options).__name__}")
        obs, infos = [], []
        for w, seed in zip(worlds, seeds):
            o, info = server.steppers[w].reset(seed=seed, options=options)
            obs.append(o)
            infos.append(info)
        return {"obs": _stack(obs), "info": columnar_infos(infos)}

    def step_batch(self, msg: dict[str, Any]) -> dict[str, Any]:
        from remoteenv.sim.server import RequestError

        server = self.server
        ops = msg.get("ops")
        num = len(server.envs)
        if (
            not isinstance(ops, list) or not 0 < len(ops) <= num
            or not all(type(op) is int and op in OPS for op in ops)
        ):
            raise RequestError(
                "protocol", f"ops must be a list of 1..{num} ints from {OPS}, got {ops!r:.200}"
            )
        n = len(ops)
        steppers = server.steppers
        for w in range(n):
            if ops[w] != OP_RESET and not steppers[w].has_reset:
                raise RequestError("state", f"step before reset on world {w} of instance {server.instance}")
        actions = self._actions(msg.get("actions"), n)
        obs: list[Any] = [None] * n
        infos: list[Any] = [None] * n
        reward = np.zeros(n, dtype=np.float64)
        terminated = np.zeros(n, dtype=np.bool_)
        truncated = np.zeros(n, dtype=np.bool_)
        final: list[Any] = []
        for w in range(n):
            op = ops[w]
            stepper = steppers[w]
            if op == OP_RESET:
                obs[w], infos[w] = stepper.reset(seed=None, options=None)
                continue
            r = stepper.step(actions[w])
            reward[w] = r["reward"]
            terminated[w] = r["terminated"]
            truncated[w] = r["truncated"]
            if op == OP_STEP_RESET or (op == OP_STEP_AUTORESET and (r["terminated"] or r["truncated"])):
                final.append([w, r["obs"], r["info"]])
                obs[w], infos[w] = stepper.reset(seed=None, options=None)
            else:
                obs[w], infos[w] = r["obs"], r["info"]
        # Short vectors go as msgpack lists: cheaper than arrays to encode and decode.
        return {
            "obs": _stack(obs),
            "reward": reward.tolist(),
            "terminated": terminated.tolist(),
            "truncated": truncated.tolist(),
            "info": columnar_infos(infos),
            "final": final,
        }

    # ------------------------------------------------------------ actions

    def _actions(self, actions: Any, n: int) -> Any:
        """The ``n`` actions, checked; indexable by world."""
        from remoteenv.sim.server import RequestError

        try:
            checked = check_actions(self._space, actions, n)
        except InvalidAction as exc:
            raise RequestError("invalid_action", str(exc)) from None
        if isinstance(checked, np.ndarray) and self._discrete:
            return checked.tolist()
        return checked
