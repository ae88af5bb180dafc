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

from remoteenv.protocol import OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET, OPS

if TYPE_CHECKING:
    from remoteenv.sim.server import RemoteControlledAgent

_SCALAR_TYPES: dict[type, tuple[type, str]] = {
    bool: (bool, "|b1"), np.bool_: (bool, "|b1"),
    int: (int, "<i8"), float: (float, "<f8"),
}


def columnar_infos(infos: list[dict[str, Any]]) -> dict[str, Any]:
    """Encode the info maps of ``n`` worlds for the wire.

    If every value is a bool, int or float (numpy scalars included) and each
    key has one type across the worlds: ``{"columns": {key: [values, mask]}}``
    with ``values`` an array of ``n`` (bool, int64 or float64; zero where the
    world lacks the key) and ``mask`` a bool array saying which worlds have
    it, both sent as msgpack lists. Otherwise ``{"maps": infos}``. Columns cost one array per key instead
    of ``n`` maps to encode and to merge on the agent side.
    """
    n = len(infos)
    kinds: dict[str, type] = {}
    for info in infos:
        for key, value in info.items():
            t = type(value)
            if t not in _SCALAR_TYPES:
                if isinstance(value, np.integer):
                    t = int
                elif isinstance(value, np.floating):
                    t = float
                else:
                    return {"maps": infos}
            base = _SCALAR_TYPES[t][0]
            if kinds.setdefault(key, base) is not base:
                return {"maps": infos}
    columns: dict[str, Any] = {}
    for key, base in kinds.items():
        values = np.zeros(n, dtype=np.dtype(_SCALAR_TYPES[base][1]))
        mask = np.zeros(n, dtype=np.bool_)
        for w, info in enumerate(infos):
            if key in info:
                values[w] = info[key]
                mask[w] = True
        columns[key] = [values.tolist(), mask.tolist()]
    return {"columns": columns}


def _stack(items: list[Any]) -> Any:
    """One array of shape (n, ...) if every item is an array of one shape and dtype, else the list."""
    first = items[0]
    if isinstance(first, np.ndarray) and all(
        isinstance(x, np.ndarray) and x.shape == first.shape and x.dtype == first.dtype for x in items
    ):
        return np.stack(items)
    return items


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
        from remoteenv.sim.server import RequestError, validate_action

        space = self._space
        if self._box and isinstance(actions, np.ndarray):
            if actions.shape != (n, *space.shape):
                raise RequestError(
                    "invalid_action",
                    f"actions of shape {actions.shape} do not fit {n} worlds of {space}",
                )
            if actions.dtype != space.dtype:
                if not np.can_cast(actions.dtype, space.dtype, casting="same_kind"):
                    raise RequestError("invalid_action", f"actions of dtype {actions.dtype} do not fit {space}")
                actions = actions.astype(space.dtype)
            inside = (actions >= space.low) & (actions <= space.high)  # NaN compares False
            if not inside.all():
                bad = int(np.flatnonzero(~inside.reshape(n, -1).all(axis=1))[0])
                raise RequestError("invalid_action", f"action {actions[bad]!r:.200} of world {bad} is not in {space}")
            return actions
        if self._discrete and isinstance(actions, np.ndarray) and actions.dtype.kind in "iu":
            if actions.shape != (n,):
                raise RequestError("invalid_action", f"actions of shape {actions.shape} do not fit {n} worlds of {space}")
            start = int(space.start)
            inside = (actions >= start) & (actions < start + int(space.n))
            if not inside.all():
                bad = int(np.flatnonzero(~inside)[0])
                raise RequestError("invalid_action", f"action {actions[bad]} of world {bad} is not in {space}")
            return actions.tolist()
        if not isinstance(actions, list) or len(actions) != n:
            raise RequestError(
                "invalid_action", f"actions must be an array or list with one action per world ({n})"
            )
        return [validate_action(self.server.envs[w], a) for w, a in enumerate(actions)]
