"""The batch info codec: the sim's columnar encoding, over the wire, into the
agent's Gymnasium vector infos; the same as Gymnasium's own merge, world by world."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from gymnasium.vector import VectorEnv

from remoteenv.wire import protocol
from remoteenv.wire.messages.batch_encoding import columnar_infos, merge_infos, stack


class _Merger(VectorEnv):
    """Gymnasium's ``_add_info`` for ``num_envs`` worlds (no env behind it)."""

    def __init__(self, num_envs: int) -> None:
        self.num_envs = num_envs


def gymnasium_merge(per_world: list[dict[str, Any]], idx: list[int], num_envs: int) -> dict[str, Any]:
    merger, infos = _Merger(num_envs), {}
    for info, i in zip(per_world, idx):
        infos = merger._add_info(infos, info, i)
    return infos


def over_the_wire(packed: dict[str, Any]) -> dict[str, Any]:
    return protocol.unpack(protocol.pack(packed))


def assert_same(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert set(a) == set(b)
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, dict):
            assert_same(x, y)
        else:
            assert x.dtype == y.dtype, key
            np.testing.assert_array_equal(x, y, err_msg=key)


CASES = {
    "scalars": [{"a": 1, "b": 0.5, "c": True}, {"a": 2, "b": 1.5, "c": False}],
    "some keys missing": [{"a": 1}, {}, {"a": 3, "b": 2.5}],
    "numpy scalars": [{"a": np.int32(4), "b": np.float32(0.25), "c": np.bool_(True)}, {"a": np.int64(5)}],
    "no keys at all": [{}, {}],
}


@pytest.mark.parametrize("name", list(CASES))
def test_columns_round_trip_like_gymnasium(name):
    per_world = CASES[name]
    n = len(per_world) + 2  # the worlds sit at an offset in a bigger vector
    idx = np.arange(2, 2 + len(per_world))
    packed = columnar_infos(per_world)
    assert "columns" in packed
    merged: dict[str, Any] = {}
    merge_infos(merged, over_the_wire(packed), idx, n, _Merger(n)._add_info)
    # numpy numbers keep their dtype, as in Gymnasium's merge (issue 14); np.bool_ becomes bool.
    plain = [{k: v.item() if isinstance(v, np.bool_) else v for k, v in info.items()} for info in per_world]
    assert_same(merged, gymnasium_merge(plain, idx.tolist(), n))


@pytest.mark.parametrize(
    "per_world",
    [
        [{"a": 1}, {"a": 1.5}],  # one key, two types
        [{"name": "x"}, {"name": "y"}],  # not a scalar
        [{"nested": {"a": 1}}],
    ],
)
def test_anything_else_travels_as_maps_and_merges_like_gymnasium(per_world):
    packed = columnar_infos(per_world)
    assert packed == {"maps": per_world}
    n = len(per_world)
    merged: dict[str, Any] = {}
    merge_infos(merged, over_the_wire(packed), np.arange(n), n, _Merger(n)._add_info)
    assert_same(merged, gymnasium_merge(per_world, list(range(n)), n))


def test_two_slices_merge_into_one_vector_info():
    n = 4
    merged: dict[str, Any] = {}
    add = _Merger(n)._add_info
    merge_infos(merged, over_the_wire(columnar_infos([{"a": 1}, {"a": 2}])), np.array([0, 1]), n, add)
    merge_infos(merged, over_the_wire(columnar_infos([{}, {"a": 4}])), np.array([2, 3]), n, add)
    assert merged["a"].tolist() == [1, 2, 0, 4] and merged["_a"].tolist() == [True, True, False, True]


def test_a_column_after_a_map_of_another_kind_goes_through_gymnasium():
    n = 2
    merged: dict[str, Any] = {}
    add = _Merger(n)._add_info
    merge_infos(merged, {"maps": [{"a": "text"}]}, np.array([0]), n, add)
    merge_infos(merged, over_the_wire(columnar_infos([{"a": 3}])), np.array([1]), n, add)
    assert merged["a"].tolist() == ["text", 3] and merged["_a"].tolist() == [True, True]


def test_stack_gives_one_array_only_for_arrays_of_one_shape_and_dtype():
    same = [np.zeros(3, np.float32), np.ones(3, np.float32)]
    assert stack(same).shape == (2, 3)
    mixed = [np.zeros(3, np.float32), np.zeros(2, np.float32)]
    assert stack(mixed) is mixed
    assert stack([1, 2]) == [1, 2]
