"""Putting the replies of a vector call together into Gymnasium's batch form.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`). Each sim
process answers for its slice of worlds in ``step_batch`` form (see
:mod:`remoteenv.wire.protocol`: ``obs``, ``reward``, ``terminated``,
``truncated``, ``info`` as columns or maps, ``final``); :func:`assemble`
writes the slices into one obs batch, three arrays and the vector info dict
(``key`` array plus ``_key`` mask, through :func:`remoteenv.wire.messages.batch_encoding.merge_infos`).
Plain ``step``/``reset`` replies (one world per process) are first put in
that form with :func:`step_reply_as_batch` and :func:`reset_reply_as_batch`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import concatenate, create_empty_array

from remoteenv.agent.connection.shared_lane_client import RegionReply
from remoteenv.wire.codec.scalar_types import restore_info, restore_scalars
from remoteenv.wire.messages.batch_encoding import AddInfo, merge_infos


class ObsBatch:
    """The obs batch of ``num_envs`` worlds of one observation space.

    A Box space's batch is one ``(num_envs, *shape)`` array, written in place;
    any other space's is a list of per-world obs, concatenated into
    Gymnasium's batch layout when returned (:meth:`for_gym`).
    """

    def __init__(self, space: spaces.Space, num_envs: int) -> None:
        self.space = space
        self.num_envs = num_envs
        self.box = isinstance(space, spaces.Box)

    def fresh(self, last: Any, full: bool) -> Any:
        """A new batch: empty if every world will be written (``full``), else a copy of ``last``."""
        if self.box:
            if full or last is None:
                return np.empty((self.num_envs, *self.space.shape), dtype=self.space.dtype)  # type: ignore[misc]
            return last.copy()
        if full or last is None:
            return [None] * self.num_envs
        return list(last)

    def put(self, obs: Any, idx: np.ndarray, items: Any) -> None:
        """Write the obs ``items`` of worlds ``idx`` into the batch ``obs``."""
        if self.box:
            obs[idx] = items if isinstance(items, np.ndarray) else np.stack(items)
        else:
            for j, i in enumerate(idx):
                obs[int(i)] = items[j]

    def rows(self, obs: Any, lo: int, hi: int) -> list[Any]:
        """Worlds ``lo .. hi - 1`` of the batch ``obs``, each a fresh copy for a Box space."""
        return [np.array(obs[i]) if self.box else obs[i] for i in range(lo, hi)]

    def for_gym(self, obs: Any) -> Any:
        """The batch as a Gymnasium vector env returns it."""
        if self.box:
            return obs
        out = create_empty_array(self.space, self.num_envs)
        assert out is not None
        return concatenate(self.space, obs, out)


def step_reply_as_batch(reply: dict[str, Any]) -> dict[str, Any]:
    """A plain ``step`` reply (one world) in ``step_batch`` form."""
    reply = restore_scalars(reply)
    return {
        "obs": [reply["obs"]],
        "reward": [reply["reward"]],
        "terminated": [reply["terminated"]],
        "truncated": [reply["truncated"]],
        "info": {"maps": [reply["info"]]},
        "final": [],
    }


def reset_reply_as_batch(reply: dict[str, Any], as_step: bool = False) -> dict[str, Any]:
    """A plain ``reset`` reply (one world) in ``reset_batch`` form, or with
    ``as_step`` in ``step_batch`` form (reward 0, not terminated, not truncated)."""
    reply = restore_scalars(reply)
    result: dict[str, Any] = {"obs": [reply["obs"]], "info": {"maps": [reply["info"]]}}
    if as_step:
        result.update(reward=[0.0], terminated=[False], truncated=[False], final=[])
    return result


def _finals(result: dict[str, Any]) -> list[Any]:
    """The ``final`` entries of a ``step_batch`` result, their info values
    typed as ``final_types`` says (see :mod:`remoteenv.wire.codec.scalar_types`)."""
    final, types = result["final"], result.get("final_types")
    if isinstance(types, list) and len(types) == len(final):
        for (_, _, info), info_types in zip(final, types):
            restore_info(info, info_types)
    return final


def hold_big_ints(vector_infos: dict[str, Any], env_info: dict[str, Any], num_envs: int) -> dict[str, Any]:
    """``vector_infos`` made ready for ``env_info``'s Python ints beyond int64
    (Gymnasium's merge types a new int key ``int``, and writing 2**70 there
    raises ``OverflowError``): such a key's array becomes an object array
    holding each world's value as a Python int. Changes and returns ``vector_infos``."""
    for key, value in env_info.items():
        if type(value) is not int or _INT64_MIN <= value <= _INT64_MAX:
            continue
        arr = vector_infos.get(key)
        if arr is None:
            vector_infos[key] = np.full(num_envs, None, dtype=object)
        elif isinstance(arr, np.ndarray) and arr.dtype.kind in "iub" and arr.shape == (num_envs,):
            held = np.empty(num_envs, dtype=object)
            held[:] = arr.tolist()
            vector_infos[key] = held
    return vector_infos


_INT64_MIN, _INT64_MAX = -(2**63), 2**63 - 1


def hold_nones(vector_infos: dict[str, Any], env_info: dict[str, Any], num_envs: int) -> dict[str, Any]:
    """``vector_infos`` made ready for one more rule than Gymnasium's merge of
    ``env_info`` (one world's): a world's None for a key other worlds gave a
    number or an array (a delayed lock-step world's ``latency_ticks`` while its
    default action acts, its ``applied_action`` for a scene whose default is
    "no action") turns that key's array into an object array holding each
    world's value as it came. Changes and returns ``vector_infos``."""
    for key, value in env_info.items():
        arr = vector_infos.get(key)
        if value is None and isinstance(arr, np.ndarray) and arr.dtype != object:
            held = np.empty(num_envs, dtype=object)
            for w in range(num_envs):
                held[w] = arr[w] if arr.ndim > 1 else arr[w].item()
            vector_infos[key] = held
    return vector_infos


def assemble(
    results: dict[int, dict[str, Any]],
    slices: Sequence[tuple[int, int]],
    obs_batch: ObsBatch,
    add_info: AddInfo,
) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """``(obs, rewards, terminated, truncated, infos)`` of all worlds from the
    ``step_batch``-form result of each process (``results[p]`` covers worlds
    ``slices[p]``). ``obs`` is the raw batch (see :meth:`ObsBatch.for_gym`).
    A world reset within the step has its ended episode's last obs and info in
    ``infos["final_obs"]`` and ``infos["final_info"]``."""
    n = obs_batch.num_envs
    infos: dict[str, Any] = {}
    regions = [r for r in results.values() if isinstance(r, RegionReply)]
    if regions:
        if len(regions) == len(results) and obs_batch.box:
            return _from_regions(results, slices, obs_batch)  # type: ignore[arg-type]
        results = {p: r.as_reply() if isinstance(r, RegionReply) else r for p, r in results.items()}
    if len(results) == 1 and obs_batch.box and isinstance(results[0]["obs"], np.ndarray):
        r = results[0]  # one process: its fresh arrays are the batch
        idx = np.arange(n)
        for w, fobs, finfo in _finals(r):
            add_info(infos, {"final_obs": fobs, "final_info": finfo}, w)
        merge_infos(infos, r["info"], idx, n, add_info)
        return (
            r["obs"],
            np.asarray(r["reward"], dtype=np.float64),
            np.asarray(r["terminated"], dtype=np.bool_),
            np.asarray(r["truncated"], dtype=np.bool_),
            infos,
        )
    obs = obs_batch.fresh(None, full=True)
    rewards = np.empty(n, dtype=np.float64)
    terminated = np.empty(n, dtype=np.bool_)
    truncated = np.empty(n, dtype=np.bool_)
    for p, (lo, hi) in enumerate(slices):
        r = results[p]
        idx = np.arange(lo, hi)
        obs_batch.put(obs, idx, r["obs"])
        rewards[lo:hi] = r["reward"]
        terminated[lo:hi] = r["terminated"]
        truncated[lo:hi] = r["truncated"]
        for w, fobs, finfo in _finals(r):
            add_info(infos, {"final_obs": fobs, "final_info": finfo}, lo + w)
        merge_infos(infos, r["info"], idx, n, add_info)
    return obs, rewards, terminated, truncated, infos


def _from_regions(
    results: dict[int, RegionReply], slices: Sequence[tuple[int, int]], obs_batch: ObsBatch
) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """:func:`assemble` when every process answered in its shared region: each
    block copied once into fresh arrays, the info columns merged as
    :func:`~remoteenv.wire.messages.batch_encoding.merge_infos` merges columns every world has."""
    n = obs_batch.num_envs
    space = obs_batch.space
    if len(slices) == 1:
        return from_one_region(results[0], n, space.dtype)
    obs = np.empty((n, *space.shape), dtype=space.dtype)  # type: ignore[misc]
    rewards = np.empty(n, dtype=np.float64)
    terminated = np.empty(n, dtype=np.bool_)
    truncated = np.empty(n, dtype=np.bool_)
    infos: dict[str, Any] = {}
    for p, (lo, hi) in enumerate(slices):
        r = results[p]
        obs[lo:hi] = r.obs
        rewards[lo:hi] = r.reward
        np.not_equal(r.terminated, 0, out=terminated[lo:hi])  # any nonzero byte is true
        np.not_equal(r.truncated, 0, out=truncated[lo:hi])
        for key, mask_key, dtype, values in r.columns:
            column = infos.get(key)
            if column is None:
                column = infos[key] = np.zeros(n, dtype=dtype)
                infos[mask_key] = np.zeros(n, dtype=np.bool_)
            column[lo:hi] = values
            infos[mask_key][lo:hi] = True
    return obs, rewards, terminated, truncated, infos


def from_one_region(
    r: RegionReply, n: int, obs_dtype: Any
) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """:func:`_from_regions` for one process's region, which holds every world:
    the same arrays, each made in one call (the info masks are the rows of one)."""
    infos: dict[str, Any] = {}
    columns = r.columns
    if columns:
        masks = np.ones((len(columns), n), dtype=np.bool_)
        for (key, mask_key, dtype, values), mask in zip(columns, masks):
            infos[key] = np.array(values, dtype=dtype)
            infos[mask_key] = mask
    return (
        np.array(r.obs, dtype=obs_dtype),
        np.array(r.reward, dtype=np.float64),
        r.terminated != 0,  # any nonzero byte is true
        r.truncated != 0,
        infos,
    )


__all__ = ["ObsBatch", "assemble", "from_one_region", "reset_reply_as_batch", "step_reply_as_batch"]
