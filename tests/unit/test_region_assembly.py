"""A vector step answered in the sims' regions assembles the same way whether
one process's region holds every world or the worlds are split over several:
the same values, dtypes, info keys and masks, in fresh writable arrays that
no later region write reaches."""

from __future__ import annotations

import os

import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.agent.connection.shared_lane_client import RegionReply
from remoteenv.agent.vector.vector_results import ObsBatch, assemble
from remoteenv.wire.shared_memory.shared_batch import SharedLayout, create_region

pytestmark = pytest.mark.skipif(not hasattr(os, "memfd_create"), reason="memfd_create is Linux only")

N = 6
COLUMNS = [("reward_dist", np.dtype("<f8"), True), ("steps", np.dtype("<i8"), True)]


def _region(k: int, rows: slice, data: dict[str, np.ndarray]):
    fd, arrays = create_region(SharedLayout(k, "<f4", (2,), "<f8", (3,), info_columns=4))
    os.close(fd)
    arrays.obs[:k] = data["obs"][rows]
    arrays.reward[:k] = data["reward"][rows]
    arrays.terminated[:k] = data["terminated"][rows]
    arrays.truncated.view(np.uint8)[:k] = data["truncated"][rows] * 2  # any nonzero byte is true
    for c, (key, dt, _) in enumerate(COLUMNS):
        arrays.info_column(c, dt)[:k] = data[key][rows]
    return arrays


def test_one_region_and_two_assemble_alike():
    rng = np.random.default_rng(0)
    data = {
        "obs": rng.random((N, 3)),
        "reward": rng.random(N),
        "terminated": rng.random(N) < 0.5,
        "truncated": rng.random(N) < 0.5,
        "reward_dist": rng.random(N),
        "steps": rng.integers(0, 50, N),
    }
    batch = ObsBatch(spaces.Box(-np.inf, np.inf, (3,), np.float64), N)
    one = [_region(N, slice(0, N), data)]
    two = [_region(4, slice(0, 4), data), _region(2, slice(4, N), data)]
    try:
        got_one = assemble({0: RegionReply(one[0], 1, COLUMNS, N)}, [(0, N)], batch, lambda *a: None)
        got_two = assemble(
            {0: RegionReply(two[0], 1, COLUMNS, 4), 1: RegionReply(two[1], 1, COLUMNS, 2)},
            [(0, 4), (4, N)],
            batch,
            lambda *a: None,
        )
        for a, b in zip(got_one[:4], got_two[:4]):
            np.testing.assert_array_equal(a, b)
            assert a.dtype == b.dtype and a.flags.writeable and a.flags.owndata
        assert list(got_one[4]) == list(got_two[4]) == ["reward_dist", "_reward_dist", "steps", "_steps"]
        for key in got_one[4]:
            np.testing.assert_array_equal(got_one[4][key], got_two[4][key])
            assert got_one[4][key].dtype == got_two[4][key].dtype
        np.testing.assert_array_equal(got_one[3], data["truncated"])  # bytes of 2 read as true
        one[0].obs[:] = -1.0  # the next reply written into the region
        one[0].info_column(0, COLUMNS[0][1])[:] = -1.0
        np.testing.assert_array_equal(got_one[0], data["obs"])
        np.testing.assert_array_equal(got_one[4]["reward_dist"], data["reward_dist"])
    finally:
        for arrays in one + two:
            arrays.close()
