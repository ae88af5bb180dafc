"""Issue 19, the agent's end of the shared-memory region: mapped only when
sealed against shrinking and laid out for the env's observations, else a
warning and the msgpack path; flags read back as proper bools. No process is
started: the region is a memfd of this process, offered through a stand-in
connection."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from fakes import RegionConn
from gymnasium import spaces

from remoteenv.agent.connection import shared_lane_client as shared_lane
from remoteenv.wire.shared_memory.shared_batch import SharedLayout, create_region

OBS = spaces.Box(-1.0, 1.0, (3,), np.float32)
linux_only = pytest.mark.skipif(not hasattr(os, "memfd_create"), reason="memfd_create is Linux only")


@linux_only
def test_an_unsealed_region_is_not_mapped_and_the_lane_falls_back_with_a_warning():
    layout = SharedLayout(4, "<i8", (), "<f4", (3,))
    fd = os.memfd_create("unsealed-region", os.MFD_CLOEXEC)  # what a sim without seals would offer
    try:
        os.ftruncate(fd, layout.size)
        with pytest.warns(RuntimeWarning, match="not sealed against shrinking"):
            assert shared_lane.attach(RegionConn(fd, layout)) is None  # type: ignore[arg-type]
    finally:
        os.close(fd)


@linux_only
def test_a_sealed_region_cannot_be_truncated_under_the_agents_mapping():
    layout = SharedLayout(4, "<i8", (), "<f4", (3,))
    fd, sim_end = create_region(layout)
    try:
        agent_end = shared_lane.attach(RegionConn(fd, layout))  # type: ignore[arg-type]
        assert agent_end is not None
        with pytest.raises(OSError):
            os.ftruncate(fd, 0)  # the sim (or anyone with the fd) cannot shrink it: no SIGBUS
        agent_end.obs[3] = [1.0, 2.0, 3.0]
        assert sim_end.obs[3].tolist() == [1.0, 2.0, 3.0]
        agent_end.close()
    finally:
        sim_end.close()
        os.close(fd)


@linux_only
def test_a_region_laid_out_for_other_observations_is_not_used():
    layout = SharedLayout(4, "<i8", (), "<f8", (3,))  # float64 rows for a float32 space
    fd, sim_end = create_region(layout)
    try:
        lanes = shared_lane.SharedLanes(OBS)
        with pytest.warns(RuntimeWarning, match="laid out for observations"):
            assert lanes.get(0, RegionConn(fd, layout), True) is None  # type: ignore[arg-type]
        lanes.close()
    finally:
        sim_end.close()
        os.close(fd)


@linux_only
def test_flags_from_the_region_are_proper_bools_whatever_byte_the_sim_wrote():
    layout = SharedLayout(2, "<i8", (), "<f4", (3,))
    fd, sim_end = create_region(layout)
    try:
        lanes = shared_lane.SharedLanes(OBS)
        conn = RegionConn(fd, layout)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert lanes.put_actions(0, conn, True, np.zeros(2, np.int64))  # type: ignore[arg-type]
        sim_end.terminated.view(np.uint8)[:] = [2, 0]
        reply: dict = {}
        lanes.fill(0, reply, 2)
        assert reply["terminated"].tolist() == [True, False] and (~reply["terminated"]).tolist() == [False, True]
        lanes.close()
    finally:
        sim_end.close()
        os.close(fd)
