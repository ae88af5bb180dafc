"""The sim's pipe channel hands over a request found in the shared region as
the map its frame decodes to, in the agent's order among the pipe's frames."""

from __future__ import annotations

import socket

from remoteenv.sim.transport.channels import PipeChannel, region_request
from remoteenv.wire import protocol


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
