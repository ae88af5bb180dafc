"""A scene's info columns in their wire form: the pipe's columns, the region's,
and the per-world maps agree on every value, an int beyond int64 included
(a column is int64; only a per-world map carries it)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from remoteenv.sim.scene.batch_result import BatchResult, widened
from remoteenv.sim.stepping.plain_region_step import batch_infos
from remoteenv.sim.transport.shared_lane_server import SharedLane
from remoteenv.wire.messages.batch_encoding import COLUMN_KINDS, columnar_infos

BIG = 2**63 + 5


def _batch(infos: dict, python: frozenset = frozenset()) -> BatchResult:
    return BatchResult(np.zeros((3, 2)), np.zeros(3), np.zeros(3, dtype=np.bool_), infos, python_scalars=python)


def _per_world(batch: BatchResult) -> dict:
    return columnar_infos([batch.world_info(w) for w in range(3)])


def test_a_python_uint64_beyond_int64_goes_as_maps_with_its_value() -> None:
    batch = _batch({"count": np.array([1, BIG, 3], dtype=np.uint64)}, frozenset({"count"}))
    assert batch.wire_columns() is None
    assert batch_infos(batch) == _per_world(batch) == {"maps": [{"count": 1}, {"count": BIG}, {"count": 3}]}


def test_a_python_int_list_beyond_int64_goes_as_maps_with_its_value() -> None:
    batch = _batch({"count": [1, -(2**63) - 1, 3]})
    assert batch.wire_columns() is None
    assert batch_infos(batch) == _per_world(batch)


def test_columns_within_int64_keep_the_column_form() -> None:
    batch = _batch(
        {"count": np.array([1, 2**63 - 1, 3], dtype=np.uint64), "flag": np.array([True, False, True])},
        frozenset({"count"}),
    )
    assert batch.wire_columns() == _per_world(batch)
    assert batch.wire_columns() == {
        "columns": {"count": [[1, 2**63 - 1, 3], [True] * 3], "flag": [[True, False, True], [True] * 3]}
    }


def test_the_region_leaves_a_column_it_cannot_hold_exactly_to_the_pipe() -> None:
    lane = SharedLane(spaces.Box(-1, 1, (2,)), spaces.Box(-np.inf, np.inf, (2,)), 3)
    try:
        big = _batch({"count": np.array([1, BIG, 3], dtype=np.uint64)}, frozenset({"count"}))
        assert lane._columns(big) is None
        fits = _batch({"count": np.array([1, 2, 3], dtype=np.uint64)}, frozenset({"count"}))
        ((key, values, python),) = lane._columns(fits)
        assert (key, values.dtype, values.tolist(), python) == ("count", np.dtype(np.int64), [1, 2, 3], True)
    finally:
        lane.close()


def test_every_column_kind_the_wire_carries_widens_to_python_scalars() -> None:
    """The sim widens a python-scalar column of each kind the wire takes as a
    column (``COLUMN_KINDS``) into the dtype whose ``tolist()`` gives bools, ints or floats."""
    python_type = {"b": bool, "i": int, "u": int, "f": float}
    samples = {"b": np.bool_, "i": np.int16, "u": np.uint8, "f": np.float32}
    assert set(samples) == COLUMN_KINDS
    for kind, dtype in samples.items():
        wide = widened(np.array([1, 0, 1], dtype=dtype))
        assert wide is not None and wide.dtype.kind in COLUMN_KINDS
        assert [type(v) for v in wide.tolist()] == [python_type[kind]] * 3
