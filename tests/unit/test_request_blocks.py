"""The agent writes each request posted in a region's fast lane into its
blocks: the actions every time, the ops of the plan it was given (the shared
all-step plan, then another plan, then the shared one again), the worlds when
named, and rows for a smaller request. No process is started: the region is a
memfd of this process, offered through a stand-in connection."""

from __future__ import annotations

import os

import numpy as np
import pytest
from fakes import RegionConn
from gymnasium import spaces

from remoteenv.agent.connection import shared_lane_client as shared_lane
from remoteenv.agent.vector.autoreset import plan_ops
from remoteenv.wire.protocol import OP_RESET, OP_STEP
from remoteenv.wire.shared_memory.shared_batch import SharedLayout, create_region

OBS = spaces.Box(-1.0, 1.0, (3,), np.float32)
K = 4


@pytest.mark.skipif(not hasattr(os, "memfd_create"), reason="memfd_create is Linux only")
def test_every_posted_request_is_in_the_region_whatever_the_plan_before_it() -> None:
    from gymnasium.vector import AutoresetMode

    layout = SharedLayout(K, "<f4", (2,), "<f4", (3,), info_columns=2)
    fd, sim_end = create_region(layout)
    lanes = shared_lane.SharedLanes(OBS)
    conn = RegionConn(fd, layout)
    try:
        every_step = plan_ops(AutoresetMode.NEXT_STEP, np.zeros(K, np.bool_), np.zeros(K, np.int64), None)
        one_reset = plan_ops(AutoresetMode.NEXT_STEP, np.eye(K, dtype=np.bool_)[1], np.zeros(K, np.int64), None)
        assert one_reset.tolist() == [OP_STEP, OP_RESET, OP_STEP, OP_STEP]
        plans = [every_step, one_reset, every_step, every_step, one_reset.copy(), every_step]
        for i, ops in enumerate(plans):
            actions = np.full((K, 2), 0.1 * i, np.float32)
            assert lanes.post(0, conn, True, ops, actions) == i + 1  # type: ignore[arg-type]
            assert sim_end.ops is not None
            assert sim_end.ops.tolist() == ops.tolist(), i
            assert sim_end.actions.tolist() == actions.tolist(), i
            assert conn.posted[-1] == (K, False, OP_RESET not in ops.tolist()), i  # a plain step or not
            lanes.forget(0)  # its reply is not read here
        # A smaller request that names its worlds: its rows and worlds, the rest as they were.
        ops = np.array([OP_STEP, OP_STEP], np.int64)
        seq = lanes.post(0, conn, True, ops, np.ones((2, 2), np.float32), worlds=np.array([3, 1]))  # type: ignore[arg-type]
        assert seq == len(plans) + 1 and conn.posted[-1] == (2, True, True)
        assert sim_end.ops[:2].tolist() == [OP_STEP, OP_STEP] and sim_end.worlds is not None
        assert sim_end.worlds[:2].tolist() == [3, 1] and sim_end.actions[:2].tolist() == [[1.0, 1.0]] * 2
    finally:
        lanes.close()
        sim_end.close()
        os.close(fd)
