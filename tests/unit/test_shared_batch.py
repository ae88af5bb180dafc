"""The shared-memory region of batched steps: its layout as sent, the sim's
end and the agent's mapping (no process is started: the agent maps the
sim's file through this process's own /proc entry)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.transport.checks import RequestError
from remoteenv.sim.transport.shared_lane_server import SharedLane, layout_for
from remoteenv.wire.shared_memory.shared_batch import MAX_SHARED_BYTES, SharedLayout, create_region, map_region
from remoteenv.wire.wire_errors import ProtocolError

BOX_ACT = spaces.Box(-1, 1, (2,), np.float32)
BOX_OBS = spaces.Box(-np.inf, np.inf, (10,), np.float64)
linux_only = pytest.mark.skipif(not hasattr(os, "memfd_create"), reason="memfd_create is Linux only")


def test_layouts_follow_the_spaces():
    assert layout_for(BOX_ACT, BOX_OBS, 8) == SharedLayout(8, "<f4", (2,), "<f8", (10,))
    assert layout_for(spaces.Discrete(3), BOX_OBS, 4) == SharedLayout(4, "<i8", (), "<f8", (10,))
    assert layout_for(spaces.Dict({"a": BOX_ACT}), BOX_OBS, 4) is None
    assert layout_for(BOX_ACT, spaces.Discrete(5), 4) is None


def test_a_layout_survives_the_wire_and_every_block_is_aligned():
    layout = SharedLayout(3, "<f4", (2,), "<f8", (10,))
    assert SharedLayout.from_wire(layout.to_wire()) == layout
    assert layout.size == 64 + 256 + 64 + 64 + 64


@pytest.mark.parametrize(
    "bad",
    [
        None,
        {"worlds": 0, "actions": ["<f4", [2]], "obs": ["<f8", [10]]},
        {"worlds": 2, "actions": ["object", [2]], "obs": ["<f8", [10]]},
        {"worlds": 2, "actions": ["<f4", [-2]], "obs": ["<f8", [10]]},
        {"worlds": 2, "actions": ["<f4", [2]], "obs": ["<f8", [1 << 20, 1 << 10]]},
        {"worlds": 2, "actions": ["<f4", 2], "obs": ["<f8", [10]]},
        {"worlds": True, "actions": ["<f4", [2]], "obs": ["<f8", [10]]},
    ],
)
def test_a_layout_off_the_spec_or_too_large_is_refused(bad):
    with pytest.raises(ProtocolError):
        SharedLayout.from_wire(bad)


def test_the_size_bound_is_the_one_the_spec_names():
    huge = SharedLayout(1, "<f8", (MAX_SHARED_BYTES // 8,), "<f8", (1,))
    with pytest.raises(ProtocolError, match="exceeds"):
        SharedLayout.from_wire(huge.to_wire())


@linux_only
def test_both_ends_see_one_region():
    layout = SharedLayout(4, "<f4", (2,), "<f8", (10,))
    fd, sim_end = create_region(layout)
    try:
        agent_end = map_region(f"/proc/{os.getpid()}/fd/{fd}", layout)
        agent_end.actions[:2] = [[0.5, -0.5], [1.0, 0.0]]
        assert sim_end.actions[1].tolist() == [1.0, 0.0]
        sim_end.obs[3] = np.arange(10)
        sim_end.terminated[3] = True
        assert agent_end.obs[3].tolist() == list(range(10)) and bool(agent_end.terminated[3])
        agent_end.close()
    finally:
        sim_end.close()
        os.close(fd)


@linux_only
def test_the_region_is_sealed_against_resizing_before_it_is_offered():
    import fcntl

    layout = SharedLayout(4, "<f4", (2,), "<f8", (10,))
    fd, sim_end = create_region(layout)
    try:
        seals = fcntl.fcntl(fd, fcntl.F_GET_SEALS)
        wanted = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL
        assert seals & wanted == wanted and not seals & fcntl.F_SEAL_WRITE
        # Another process (here: this one through /proc, as the agent opens it) cannot resize it.
        other = os.open(f"/proc/{os.getpid()}/fd/{fd}", os.O_RDWR)
        try:
            for size in (64, layout.size * 2):
                with pytest.raises(PermissionError):
                    os.ftruncate(other, size)
            with pytest.raises(PermissionError):
                fcntl.fcntl(other, fcntl.F_ADD_SEALS, fcntl.F_SEAL_WRITE)  # the seals are sealed too
        finally:
            os.close(other)
        assert os.fstat(fd).st_size == layout.size
        sim_end.obs[3] = 1.0  # writes stay allowed
    finally:
        sim_end.close()
        os.close(fd)


@linux_only
def test_a_file_smaller_than_its_layout_is_not_mapped(tmp_path):
    small = tmp_path / "small"
    small.write_bytes(b"\0" * 64)
    with pytest.raises(OSError, match="smaller"):
        map_region(str(small), SharedLayout(4, "<f4", (2,), "<f8", (10,)))


class FakePipe:
    """Stands for the launching agent's pipe channel."""


@linux_only
def test_the_sims_end_serves_the_pipe_only(monkeypatch):
    from remoteenv.sim.transport import lane_requests
    from remoteenv.sim.transport import shared_lane_server as shared_lane

    monkeypatch.setattr(shared_lane, "PipeChannel", FakePipe)
    monkeypatch.setattr(lane_requests, "PipeChannel", FakePipe)  # the lane's requests side
    lane = SharedLane(BOX_ACT, BOX_OBS, 4)
    with pytest.raises(RequestError, match="local pipe"):
        lane.attach({}, None, None)  # e.g. a ZeroMQ client
    with pytest.raises(RequestError, match="shared_batch"):
        lane.actions(2, FakePipe())  # no region yet
    pipe = FakePipe()
    reply = lane.attach({}, pipe, None)
    assert reply["pid"] == os.getpid() and reply["layout"] == lane.layout.to_wire()  # type: ignore[union-attr]
    agent_end = map_region(f"/proc/{os.getpid()}/fd/{reply['fd']}", SharedLayout.from_wire(reply["layout"]))
    agent_end.actions[:3] = 0.25
    taken = lane.actions(3, pipe)
    agent_end.actions[:3] = 0.75  # the sim works on its own copy
    assert taken.shape == (3, 2) and (taken == 0.25).all()
    with pytest.raises(RequestError, match="1..4"):
        lane.actions(5, pipe)
    batch = BatchResult(np.ones((3, 10)), np.array([1.0, 2.0, 3.0]), np.array([False, True, False]), {})
    assert lane.reply(batch, {"columns": {}}) == {"shared": True, "info": {"columns": {}}, "final": []}
    assert agent_end.reward[:3].tolist() == [1.0, 2.0, 3.0] and agent_end.terminated[:3].tolist() == [0, 1, 0]
    assert not agent_end.truncated[:3].any() and (agent_end.obs[:3] == 1).all()
    wrong = BatchResult(np.ones((3, 10), np.float32), np.zeros(3), np.zeros(3, bool), {})
    assert lane.reply(wrong, {}) is None  # not the layout's dtype: answered the usual way
    agent_end.close()
    lane.close()
