"""The agent's wait for a reply in the shared region: a plain step's (every
world steps, none resets first) is waited for on the lane's own hot-wait
history (``LANE_SPIN_S``), a step with resets on the pipe's (``AGENT_SPIN_S``),
so that the long wait of a step that resets worlds never stops the plain
steps' waits from being hot. No process is started: the region's header is an
array of this process, answered in while the agent waits hot."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from fakes import hot_waits_allowed

from remoteenv.agent.connection import pipe_connection
from remoteenv.agent.connection.pipe_connection import PipeConnection
from remoteenv.wire.shared_memory import doorbell as doorbell_module
from remoteenv.wire.shared_memory import hot_wait
from remoteenv.wire.shared_memory.doorbell import REP_INFO, REP_SEQ, Doorbell

pytestmark = pytest.mark.skipif(not doorbell_module.SILENT, reason="the region is read without frames on x86-64 only")


@pytest.fixture(autouse=True)
def two_cpus(monkeypatch):
    hot_waits_allowed(monkeypatch)
    # Which history a wait counts on, not how long a spin may last: a busy
    # machine may deschedule this process past a window (the wait, which rang
    # the absent sim, would then not count) or long enough to be a stall.
    monkeypatch.setattr(hot_wait, "STALL_S", float("inf"))
    monkeypatch.setattr(pipe_connection, "LANE_SPIN_S", 10.0)
    monkeypatch.setattr(pipe_connection, "AGENT_SPIN_S", 5.0)


def _answer_in_the_spin(hot: hot_wait.HotWait, header: np.ndarray, seq: int) -> None:
    """The "sim" answers in the region while the agent waits hot on ``hot``."""
    spin = hot.spin

    def answering_spin() -> bool:
        header[REP_INFO] = 0
        header[REP_SEQ] = seq
        return spin()

    hot.spin = answering_spin  # type: ignore[method-assign]


@pytest.mark.parametrize("plain", [True, False])
def test_a_plain_steps_wait_counts_on_the_lanes_history_and_a_step_with_resets_on_the_pipes(plain: bool) -> None:
    agent_end, sim_end = socket.socketpair()
    header = np.zeros(16, dtype="<i8")
    conn = PipeConnection(agent_end, timeout=10.0)
    try:
        assert conn._lane_hot.window_s == pipe_connection.LANE_SPIN_S > conn._hot.window_s
        seq = conn.post(Doorbell(header), 4, False, plain=plain)
        for hot in (conn._lane_hot, conn._hot):
            _answer_in_the_spin(hot, header, seq)
        reply = conn.receive(seq)
        assert reply == {"seq": seq, "ok": True, "region": True}
        lane_counted, pipe_counted = conn._lane_hot._last_wait_s > 0, conn._hot._last_wait_s > 0
        assert (lane_counted, pipe_counted) == (plain, not plain)
    finally:
        conn.close()
        agent_end.close()
        sim_end.close()
