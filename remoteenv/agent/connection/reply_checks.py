"""Every reply checked against the handshake before anything reaches the user.

Runs in the agent process. A sim is a peer the agent does not control (an
attached server, a robot bridge, a Ray node), so the fields of each ``ok``
reply are checked against the spec (:mod:`remoteenv.wire.protocol`) and the
env's spaces before they are used: observations of the observation space's
dtype and shape (every member of a Dict or Tuple), rewards that are numbers,
flags that are bools, info maps with str keys, lists as long as the worlds
asked for, ``final`` positions in range and distinct, render frames uint8
``H x W x 3``. A violation raises :class:`~remoteenv.agent.errors.RemoteProtocolError`
naming the command, the field and the sim; nothing of the reply is used.
Values are not checked against the space's bounds (simulators leave them,
as Gymnasium's own envs do).

The batch checks are vectorised: one ``np.asarray`` per field and a dtype
and shape comparison, which also hands the later assembly arrays in place of
lists (a reply's ``reward``, ``terminated``, ``truncated`` and info columns
are replaced by the checked arrays). Per-world Python runs only where the
reply is per-world already (lists of observations, info maps, ``final``).
A reply in a shared region (the fast lane) holds numbers of the dtypes and
shapes its layout fixed: the region's when it was mapped, the info columns'
when the sim announced them (:meth:`ReplyChecks.info_layout`); each such
reply is taken only for the request it names and the layout it was written
in (:mod:`remoteenv.agent.connection.shared_lane_client`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.agent.errors import RemoteProtocolError
from remoteenv.wire.messages.batch_encoding import COLUMN_KINDS
from remoteenv.wire.wire_errors import short_repr

#: Spaces whose values are numpy arrays of the space's dtype and shape.
_ARRAY_SPACES = (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)
#: numpy kinds a list of numbers may have (signed, unsigned, float).
_NUMBER_KINDS = frozenset("iuf")
#: What a list of bools may hold (0 and 1 hash and compare as False and True).
_BOOL_VALUES = frozenset({False, True})
#: dtypes an info column in a shared region may have, and those of python scalars.
_COLUMN_DTYPES = frozenset(["|b1", "|i1", "|u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "<f2", "<f4", "<f8"])
_PYTHON_DTYPES = frozenset(["|b1", "<i8", "<f8"])
#: Longest info key of a shared region's column (characters).
_MAX_KEY_CHARS = 256


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of dtype {value.dtype} and shape {value.shape}"
    return f"{'nil' if value is None else type(value).__name__} {short_repr(value, 60)}"


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


class ValueCheck:
    """Whether a value fits one space (dtype and shape; Discrete: an int in range)."""

    def __init__(self, space: spaces.Space) -> None:
        self.space = space
        self.array = isinstance(space, _ARRAY_SPACES)
        self.dtype = np.dtype(space.dtype) if self.array else None
        self.shape: tuple[int, ...] = tuple(space.shape or ()) if self.array else ()
        if isinstance(space, spaces.Dict):
            self.members: dict[Any, ValueCheck] = {k: ValueCheck(s) for k, s in space.spaces.items()}
        elif isinstance(space, spaces.Tuple):
            self.members = dict(enumerate(ValueCheck(s) for s in space.spaces))
        else:
            self.members = {}

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` for the space, or None."""
        space = self.space
        if self.array:
            if type(value) is np.ndarray and value.dtype == self.dtype and value.shape == self.shape:
                return None
            return f"is {_describe(value)}, not an array of dtype {self.dtype} and shape {self.shape} ({space})"
        if isinstance(space, spaces.Discrete):
            if _is_number(value) and isinstance(value, (int, np.integer)):
                start = int(space.start)
                if start <= value < start + int(space.n):
                    return None
            return f"is {_describe(value)}, not an int in {space}"
        if isinstance(space, spaces.Dict):
            if not isinstance(value, dict) or value.keys() != self.members.keys():
                return f"is {_describe(value)}, not a map with the keys {sorted(self.members)}"
            for key, check in self.members.items():
                problem = check.problem(value[key])
                if problem is not None:
                    return f"[{key!r}] {problem}"
            return None
        if not isinstance(value, (list, tuple)) or len(value) != len(self.members):
            return f"is {_describe(value)}, not a list of {len(self.members)} for {space}"
        for i, check in self.members.items():
            problem = check.problem(value[i])
            if problem is not None:
                return f"[{i}] {problem}"
        return None

    def batch_problem(self, value: Any, n: int) -> str | None:
        """What is wrong with ``value`` as the obs of ``n`` worlds: one array of shape
        ``(n, *shape)`` for an array space (or a list of ``n`` fitting arrays), else
        a list of ``n`` fitting values."""
        if self.array and type(value) is np.ndarray:
            if value.dtype == self.dtype and value.shape == (n, *self.shape):
                return None
            return f"is {_describe(value)}, not an array of dtype {self.dtype} and shape {(n, *self.shape)}"
        if not isinstance(value, list) or len(value) != n:
            return f"is {_describe(value)}, not the observations of {n} world(s)"
        for j, item in enumerate(value):
            problem = self.problem(item)
            if problem is not None:
                return f"[{j}] {problem}"
        return None


class ReplyChecks:
    """The checks of one env's replies (its observation space from the handshake).

    Each method takes the connection the reply came over (to name the sim in
    errors), the reply, and returns the reply (with list fields of batch
    replies replaced by the checked arrays), or raises
    :class:`~remoteenv.agent.errors.RemoteProtocolError`.
    """

    def __init__(self, observation_space: spaces.Space) -> None:
        self.obs = ValueCheck(observation_space)

    # ------------------------------------------------------------ one world

    def reset(self, conn: Any, reply: dict[str, Any], cmd: str = "reset") -> dict[str, Any]:
        """A ``reset`` reply: ``obs`` and ``info``."""
        self._fail_on(conn, cmd, "obs", self.obs.problem(reply.get("obs")))
        self._fail_on(conn, cmd, "info", _info_problem(reply.get("info")))
        return reply

    def step(self, conn: Any, reply: dict[str, Any], cmd: str = "step") -> dict[str, Any]:
        """A ``step`` reply: ``obs``, a number ``reward``, bool flags, ``info``."""
        self.reset(conn, reply, cmd)
        reward = reply.get("reward")
        if not _is_number(reward):
            self._fail(conn, cmd, "reward", f"is {_describe(reward)}, not a number")
        for flag in ("terminated", "truncated"):
            if not isinstance(reply.get(flag), bool):
                self._fail(conn, cmd, flag, f"is {_describe(reply.get(flag))}, not a bool")
        return reply

    def frame(self, conn: Any, reply: dict[str, Any]) -> dict[str, Any]:
        """A ``render`` reply: ``frame`` nil or a uint8 ``H x W x 3`` array."""
        frame = reply.get("frame")
        if frame is not None and not (
            type(frame) is np.ndarray and frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        ):
            self._fail(conn, "render", "frame", f"is {_describe(frame)}, not nil or a uint8 array H x W x 3")
        return reply

    def attribute(self, conn: Any, cmd: str, reply: dict[str, Any]) -> dict[str, Any]:
        """A ``get_attr`` (``value``, bool ``callable``) or ``call`` (``result``) reply."""
        if cmd == "get_attr":
            if not isinstance(reply.get("callable"), bool):
                self._fail(conn, cmd, "callable", f"is {_describe(reply.get('callable'))}, not a bool")
            if "value" not in reply:
                self._fail(conn, cmd, "value", "is missing")
        elif cmd == "call" and "result" not in reply:
            self._fail(conn, cmd, "result", "is missing")
        return reply

    def sim_times(self, conn: Any, cmd: str, reply: dict[str, Any], worlds: int) -> dict[str, Any]:
        """A ``pause``/``resume`` reply: ``sim_time``, one number per world (and ``paused_s``)."""
        times = reply.get("sim_time")
        if not (isinstance(times, list) and len(times) == worlds and all(_is_number(t) for t in times)):
            self._fail(conn, cmd, "sim_time", f"is {_describe(times)}, not {worlds} number(s)")
        if cmd == "resume" and not _is_number(reply.get("paused_s", 0.0)):
            self._fail(conn, cmd, "paused_s", f"is {_describe(reply.get('paused_s'))}, not a number")
        return reply

    # ------------------------------------------------------------ batches

    def batch(self, conn: Any, cmd: str, reply: dict[str, Any], n: int, shared: bool = False) -> dict[str, Any]:
        """A ``reset_batch`` or ``step_batch`` reply for ``n`` request positions
        (``shared``: a step answered through the shared region, whose arrays are
        read from there and not checked here)."""
        if not shared:
            self._fail_on(conn, cmd, "obs", self.obs.batch_problem(reply.get("obs"), n))
        self._fail_on(conn, cmd, "info", _infos_problem(reply.get("info"), n))
        if cmd != "step_batch":
            return reply
        if not shared:
            reward = _as_array(reply.get("reward"))
            if reward is None or reward.shape != (n,) or reward.dtype.kind not in _NUMBER_KINDS:
                self._fail(conn, cmd, "reward", f"is {_describe(reply.get('reward'))}, not a list of {n} numbers")
            reply["reward"] = reward
            for flag in ("terminated", "truncated"):
                flags = _bools(reply.get(flag), n)
                if flags is None:
                    self._fail(conn, cmd, flag, f"is {_describe(reply.get(flag))}, not a list of {n} bools")
                reply[flag] = flags
        self._fail_on(conn, cmd, "final", self._finals_problem(reply.get("final"), n))
        types = reply.get("final_types")
        if types is not None and not isinstance(types, list):
            self._fail(conn, cmd, "final_types", f"is {_describe(types)}, not nil or a list")
        return reply

    def info_layout(
        self, conn: Any, layout: Any, capacity: int, after: int
    ) -> tuple[int, list[tuple[str, np.dtype, bool]]]:
        """A ``step_batch`` reply's ``info_layout`` (the typed info columns the sim
        will put in its shared region): ``(version, [(key, dtype, python), ...])``.
        The version must exceed ``after`` (the last one), the columns be at most
        ``capacity``, with distinct str keys and bool, int or float dtypes of at
        most 8 bytes (python scalars: ``|b1``, ``<i8`` or ``<f8``)."""
        cmd = "step_batch"
        if type(layout) is not dict:
            self._fail(conn, cmd, "info_layout", f"is {_describe(layout)}, not a map")
        version, columns = layout.get("version"), layout.get("columns")
        if type(version) is not int or not after < version < 1 << 62:
            self._fail(conn, cmd, "info_layout", f"version is {_describe(version)}, not an int above {after}")
        if not isinstance(columns, list) or len(columns) > capacity:
            self._fail(conn, cmd, "info_layout", f"columns are {_describe(columns)}, not a list of at most {capacity}")
        out: list[tuple[str, np.dtype, bool]] = []
        for entry in columns:
            key, dtype, python = entry if isinstance(entry, list) and len(entry) == 3 else (None, None, None)
            if type(key) is not str or len(key) > _MAX_KEY_CHARS or any(key == k for k, _, _ in out):
                self._fail(
                    conn, cmd, "info_layout", f"names a column {short_repr(entry)}: not [distinct str key, dtype, bool]"
                )
            if type(python) is not bool or dtype not in (_PYTHON_DTYPES if python else _COLUMN_DTYPES):
                self._fail(
                    conn,
                    cmd,
                    "info_layout",
                    f"column {key!r} has dtype {short_repr(dtype)} (python {short_repr(python)}): not allowed",
                )
            out.append((str(key), np.dtype(str(dtype)), bool(python)))
        return version, out

    def _finals_problem(self, final: Any, n: int) -> str | None:
        if not isinstance(final, list) or len(final) > n:
            return f"is {_describe(final)}, not a list of at most {n} [position, obs, info] entries"
        seen = set()
        for k, entry in enumerate(final):
            if not (isinstance(entry, list) and len(entry) == 3):
                return f"[{k}] is {_describe(entry)}, not [position, obs, info]"
            pos, obs, info = entry
            if type(pos) is not int or not 0 <= pos < n or pos in seen:
                return f"[{k}] names position {short_repr(pos)}, not a distinct int in 0..{n - 1}"
            seen.add(pos)
            problem = self.obs.problem(obs)
            if problem is not None:
                return f"[{k}] obs {problem}"
            problem = _info_problem(info)
            if problem is not None:
                return f"[{k}] info {problem}"
        return None

    # ------------------------------------------------------------ errors

    def _fail_on(self, conn: Any, cmd: str, field: str, problem: str | None) -> None:
        if problem is not None:
            self._fail(conn, cmd, field, problem)

    @staticmethod
    def _fail(conn: Any, cmd: str, field: str, problem: str) -> None:
        instance = getattr(conn, "instance", None)
        raise RemoteProtocolError(
            f"sim instance {instance} at {getattr(conn, 'endpoint', '?')} sent a {cmd!r} reply whose "
            f"{field!r} {problem}; the reply was not used (the server breaks the protocol, see docs/protocol.md)",
            instance=instance,
        )


def _as_array(value: Any) -> np.ndarray | None:
    """``value`` (a list or an array) as a numpy array, None if numpy cannot make
    one regular array of it."""
    if type(value) is np.ndarray:
        return value
    if not isinstance(value, list):
        return None
    try:
        return np.asarray(value)
    except (ValueError, TypeError, OverflowError):
        return None


def _bools(value: Any, n: int) -> np.ndarray | None:
    """``value`` (a list of ``n`` bools, or a bool array of shape ``(n,)``) as a
    fresh bool array; None for anything else. 0 and 1 count as the bools they
    equal (they convert exactly); strings, None and other numbers do not."""
    if type(value) is np.ndarray:
        return value if value.dtype == np.bool_ and value.shape == (n,) else None
    if not isinstance(value, list) or len(value) != n:
        return None
    try:
        if not set(value) <= _BOOL_VALUES:  # a set of at most two: cheaper than numpy's type inference
            return None
    except TypeError:  # unhashable members (lists, maps)
        return None
    return np.fromiter(value, np.bool_, n)


def _info_problem(info: Any) -> str | None:
    if type(info) is not dict:
        return f"is {_describe(info)}, not a map"
    if not all(type(k) is str for k in info):
        return f"has keys that are not strings: {short_repr(list(info)[:8])}"
    return None


def _infos_problem(infos: Any, n: int) -> str | None:
    """What is wrong with a batch reply's ``info`` (the spec's ``infos``) for ``n``
    positions; its columns are replaced by checked arrays."""
    if type(infos) is not dict or len(infos) != 1:
        return f"is {_describe(infos)}, not {{'columns': ...}} or {{'maps': ...}}"
    if "maps" in infos:
        maps = infos["maps"]
        if not isinstance(maps, list) or len(maps) != n:
            return f"'maps' is {_describe(maps)}, not a list of {n} maps"
        for j, info in enumerate(maps):
            problem = _info_problem(info)
            if problem is not None:
                return f"'maps'[{j}] {problem}"
        return None
    columns = infos.get("columns")
    if type(columns) is not dict:
        return f"is {_describe(infos)}, not {{'columns': ...}} or {{'maps': ...}}"
    for key, column in columns.items():
        if type(key) is not str or not (isinstance(column, list) and len(column) == 2):
            return f"column {short_repr(key)} is {_describe(column)}, not [values, present]"
        values, present = _as_array(column[0]), _bools(column[1], n)
        if values is None or values.shape != (n,) or values.dtype.kind not in COLUMN_KINDS:
            return f"column {key!r} values are {_describe(column[0])}, not {n} bools, ints or floats"
        if present is None:
            return f"column {key!r} present is {_describe(column[1])}, not {n} bools"
        column[0], column[1] = values, present
    return None


__all__ = ["ReplyChecks", "ValueCheck"]
