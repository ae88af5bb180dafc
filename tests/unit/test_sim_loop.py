"""The server's one loop, run in this process over a socketpair standing in for
the launcher's local pipe: requests written beforehand are answered in order,
``close`` ends serving, and the pipe's end of file or a broken frame stops it."""

from __future__ import annotations

import os
import signal
import socket
import threading
from collections.abc import Iterator
from typing import Any

import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.serving import sim_server
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.sim.serving.waits import ServingWaits
from remoteenv.wire import protocol

# A loop that misses its stop condition would wait forever: fail instead.
pytestmark = pytest.mark.timeout(60)


@pytest.fixture(autouse=True)
def keep_sigterm() -> Iterator[None]:
    """serve() installs its SIGTERM handler; give pytest its own back afterwards."""
    before = signal.getsignal(signal.SIGTERM)
    yield
    signal.signal(signal.SIGTERM, before)


@pytest.fixture
def pipe_server(tmp_path) -> Iterator[tuple[RemoteControlledAgent, socket.socket, str]]:
    """A server on one end of a socketpair; the test holds the other (the agent's) end."""
    agent_end, sim_end = socket.socketpair()
    address = f"ipc://{tmp_path}/sim-0.sock"
    server = RemoteControlledAgent([CartPoleEnv()], address, pipe_fd=sim_end.detach())
    yield server, agent_end, address
    agent_end.close()


def send(sock: socket.socket, seq: int, cmd: str, **fields: Any) -> None:
    sock.sendall(protocol.stream_frame(protocol.pack({"seq": seq, "cmd": cmd, **fields})))


def replies(sock: socket.socket) -> list[dict[str, Any]]:
    """Every reply the server wrote before it stopped."""
    sock.settimeout(0)
    data = b""
    while True:
        try:
            chunk = sock.recv(1 << 20)
        except BlockingIOError:
            break
        if not chunk:
            break
        data += chunk
    return [protocol.unpack(f) for f in protocol.StreamDecoder().feed(data)]


def test_requests_on_the_pipe_are_answered_in_order_until_close(pipe_server):
    server, agent, address = pipe_server
    send(agent, 1, "handshake", protocol=protocol.PROTOCOL_VERSION)
    send(agent, 2, "reset", seed=0)
    send(agent, 3, "step", action=1)
    send(agent, 4, "fly")
    agent.sendall(protocol.stream_frame(b"\xc1"))
    send(agent, 5, "close")
    server.serve()
    got = replies(agent)
    assert [r["seq"] for r in got] == [1, 2, 3, 4, -1, 5]
    assert [r["ok"] for r in got] == [True, True, True, False, False, True]
    assert got[2]["reward"] == 1.0
    assert not server.running and not server.orphaned
    assert not os.path.exists(address[len("ipc://") :])  # the socket file is gone


def test_the_pipes_end_of_file_stops_the_server_as_orphaned(pipe_server):
    server, agent, _ = pipe_server
    send(agent, 1, "handshake", protocol=protocol.PROTOCOL_VERSION)
    agent.shutdown(socket.SHUT_WR)  # the agent is gone (but we can still read)
    server.serve()
    assert [r["seq"] for r in replies(agent)] == [1]
    assert server.orphaned and not server.running


def test_a_frame_longer_than_the_limit_is_skipped_and_answered(pipe_server):
    # Issue 10: an oversize length no longer ends the pipe (the sim took that
    # for the agent's death and removed the live launcher's files).
    server, agent, _ = pipe_server
    size = protocol.MAX_MESSAGE_BYTES + 1
    after = protocol.stream_frame(protocol.pack({"seq": 7, "cmd": "handshake", "protocol": 1}))
    after += protocol.stream_frame(protocol.pack({"seq": 8, "cmd": "close"}))
    writer = threading.Thread(target=agent.sendall, args=(size.to_bytes(4, "little") + bytes(size) + after,))
    writer.start()
    server.serve()
    writer.join()
    got = replies(agent)
    assert [r["seq"] for r in got] == [-1, 7, 8]
    assert str(protocol.MAX_MESSAGE_BYTES) in got[0]["error"]["message"]
    assert not server.orphaned


def test_the_lock_step_loop_waits_hot_for_the_pipe_with_the_sims_patience(pipe_server, monkeypatch):
    """A late request now and then does not put the sim to sleep for the next
    one: the loop's hot wait on the pipe allows ``SIM_SPIN_PATIENCE`` late
    waits in a row (:class:`~remoteenv.wire.shared_memory.hot_wait.HotWait`)."""
    server, agent, _ = pipe_server
    made: list[ServingWaits] = []
    init = ServingWaits.__init__

    def spy(self: ServingWaits, *args: Any, **kwargs: Any) -> None:
        init(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(ServingWaits, "__init__", spy)
    send(agent, 1, "close")
    server.serve()
    assert [r["seq"] for r in replies(agent)] == [1]
    assert sim_server.SIM_SPIN_PATIENCE > 1
    assert [waits.hot.patience for waits in made] == [sim_server.SIM_SPIN_PATIENCE]
