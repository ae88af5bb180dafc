"""The sim's pipe channel hands over a request found in the shared region as
the map its frame decodes to, in the agent's order among the pipe's frames."""

from __future__ import annotations

import socket

from remoteenv.sim.transport.channels import PipeChannel
from remoteenv.wire import protocol
from remoteenv.wire.protocol import region_request


class PostedOnce:
    """A lane whose region holds request ``seq`` until it has been seen once."""

    def __init__(self, seq: int) -> None:
        self.seq = seq

    def posted(self) -> int:
        seq, self.seq = self.seq, 0
        return seq

    def settle(self) -> int:
        return 0


def _frame(seq: int, cmd: str = "ping") -> bytes:
    return protocol.stream_frame(protocol.pack({"seq": seq, "cmd": cmd}))


def test_a_region_request_comes_decoded_between_the_frames_sent_before_and_after_it():
    agent, sim = socket.socketpair()
    channel = PipeChannel(sim.detach())
    try:
        channel.lane = PostedOnce(5)
        agent.sendall(_frame(4) + _frame(6))
        got = []
        while len(got) < 3:
            got.extend(channel.receive_nowait())
        seqs = [msg["seq"] if isinstance(msg, dict) else protocol.peek_seq(msg) for _, msg in got]
        assert seqs == [4, 5, 6]
        region = got[1][1]
        # What the agent's frame for it decodes to, when it sends one (the sim sleeps).
        assert region == protocol.decode_request(protocol.pack({"seq": 5, "cmd": "step_batch", "region": True}))
        assert region == region_request(5)
        assert all(isinstance(msg, (bytes, bytearray, memoryview)) for i, (_, msg) in enumerate(got) if i != 1)
        assert channel.receive_nowait() == []  # seen once: not handed over again
    finally:
        channel.close()
        agent.close()


def test_the_ring_of_the_request_found_in_the_region_is_served_once_from_the_region():
    """The agent rang a sleeping sim for request 5 (its frame) and the sim finds
    request 5 in the region as it reads the frame: one request is handed over,
    the region's, after the frames sent before it; a ring for an earlier
    request stays a frame (served as such, found served, answered nothing)."""
    agent, sim = socket.socketpair()
    channel = PipeChannel(sim.detach())
    try:
        channel.lane = PostedOnce(5)
        ring = protocol.stream_frame(protocol.region_ring(5))
        agent.sendall(_frame(3) + protocol.stream_frame(protocol.region_ring(4)) + ring)
        got = []
        while len(got) < 3:
            got.extend(channel.receive_nowait())
        assert [msg["seq"] if isinstance(msg, dict) else protocol.peek_seq(msg) for _, msg in got] == [3, 4, 5]
        assert got[2][1] == region_request(5)
        assert protocol.decode_request(got[1][1]) == region_request(4)
        assert channel.receive_nowait() == []
    finally:
        channel.close()
        agent.close()


def test_region_ring_is_the_frame_the_fast_lane_specifies():
    assert protocol.unpack(protocol.region_ring(7)) == {"seq": 7, "cmd": "step_batch", "region": True}
