"""Issue 10, the pure parts: one frame limit enforced by the codec, a pipe
decoder that skips oversize frames and stays in step, error messages bounded
before they are built, strict field types, and ``seq`` -1 replies placed on
the request they answer. No process is started here."""

from __future__ import annotations

import numpy as np
import pytest

from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.sim.transport.checks import RequestError, protocol_version, require_driver, seed_value, world_index
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import MAX_ECHO_CHARS, short_repr

LIMIT = protocol.MAX_MESSAGE_BYTES


def test_the_limit_fits_a_rendered_1080p_and_4k_frame():
    assert len(protocol.pack({"frame": np.zeros((2160, 3840, 3), np.uint8)})) <= LIMIT


def test_pack_refuses_an_oversize_array_before_copying_it():
    big = np.broadcast_to(np.zeros(1, np.uint8), (LIMIT + 1,))  # no memory behind it
    with pytest.raises(protocol.FrameTooLarge, match=str(LIMIT)):
        protocol.pack({"x": big})


def test_pack_refuses_an_oversize_frame_and_ints_beyond_the_wire():
    with pytest.raises(protocol.FrameTooLarge):
        protocol.pack({"x": [b"y" * (LIMIT // 4)] * 5})
    for value in (2**64, -(2**63) - 1):
        with pytest.raises(ValueError, match="2\\*\\*64"):
            protocol.pack({"seed": value})
    assert protocol.unpack(protocol.pack({"seed": 2**64 - 1}))["seed"] == 2**64 - 1


def _stream(*frames: bytes) -> bytes:
    return b"".join(protocol.stream_frame(f) for f in frames)


@pytest.mark.parametrize("chunk", [1, 7, 4096, 1 << 20])
def test_the_pipe_decoder_skips_an_oversize_frame_and_stays_in_step(chunk):
    a, b = protocol.pack({"seq": 1}), protocol.pack({"seq": 2})
    size = LIMIT + 10
    junk = size.to_bytes(4, "little") + bytes(size)
    stream = protocol.stream_frame(a) + junk + protocol.stream_frame(b)
    decoder = protocol.StreamDecoder()
    items: list = []
    step = chunk if chunk > 1 else 1 << 16  # byte-by-byte through 32 MiB would take long
    head = len(protocol.stream_frame(a)) + 4
    for i in range(0, head, chunk):
        items += decoder.items(stream[i : min(i + chunk, head)])
    for i in range(head, len(stream), step):
        items += decoder.items(stream[i : i + step])
    assert items[0] == a and isinstance(items[1], protocol.FrameTooLarge) and items[2:] == [b]
    assert items[1].size == size and not decoder._buf


def test_the_legacy_feed_raises_once_and_keeps_the_frames_around_it():
    a, b = protocol.pack({"seq": 1}), protocol.pack({"seq": 2})
    size = LIMIT + 1
    decoder = protocol.StreamDecoder()
    stream = protocol.stream_frame(a) + size.to_bytes(4, "little") + bytes(size) + protocol.stream_frame(b)
    assert decoder.feed(stream) == [a]
    with pytest.raises(protocol.FrameTooLarge):
        decoder.feed(b"")
    assert decoder.feed(b"") == [b]


def test_decode_request_caps_array_and_map_lengths_before_building_them():
    frame = protocol.pack({"seq": 1, "cmd": "reset", "world": [0] * (protocol.MAX_REQUEST_ITEMS + 1)})
    with pytest.raises(protocol.ProtocolError, match="undecodable"):
        protocol.decode_request(frame)
    assert protocol.unpack(frame)["seq"] == 1  # replies are not capped this way


def test_error_replies_are_capped():
    reply = protocol.error_reply(1, "scene", "m" * 10**6, "t" * 10**6)
    assert len(reply["error"]["message"]) <= protocol.MAX_ERROR_CHARS
    assert len(reply["error"]["traceback"]) <= protocol.MAX_ERROR_CHARS


@pytest.mark.parametrize(
    "value",
    [
        list(range(10**6)),
        "s" * 10**7,
        b"b" * 10**7,
        {str(i): i for i in range(10**5)},
        10**5000,
        [[[[[[[1]]]]]]] * 10**5,
    ],
    ids=["list", "str", "bytes", "dict", "int", "nested"],
)
def test_short_repr_is_bounded(value):
    assert len(short_repr(value)) <= MAX_ECHO_CHARS


@pytest.mark.parametrize("value", [np.array(1), np.array([1]), 1.0, True, [1], "1", None, 2])
def test_only_the_int_protocol_version_passes(value):
    with pytest.raises(RequestError, match="mismatch"):
        protocol_version(value, 1, 0)
    assert protocol_version(1, 1, 0) == 1


@pytest.mark.parametrize("value", [True, 1.0, np.int64(0), [0], "0", -1])
def test_world_and_seed_fields_take_plain_ints_only(value):
    with pytest.raises(RequestError):
        world_index({"world": value}, 1) if value != -1 else world_index({"world": 5}, 1)
    if value not in (-1,) and not isinstance(value, np.integer):
        with pytest.raises(RequestError):
            seed_value(value)


def test_only_the_driver_may_step():
    require_driver(None, ("zmq", b"a"), 0, 0, "step")
    require_driver(("pipe", None), ("pipe", None), 0, 0, "step")
    with pytest.raises(RequestError, match="driven by another connection") as err:
        require_driver(("pipe", None), ("zmq", b"a"), 0, 0, "step")
    assert err.value.kind == "state"


class _Frames(SimConnection):
    """A connection whose transport replays canned reply frames."""

    def __init__(self) -> None:
        super().__init__("test://", timeout=0.05)
        self.sent: list[bytes] = []
        self.inbox: list[bytes] = []

    def _send_frame(self, payload: bytes) -> None:
        self.sent.append(payload)

    def _recv_frame(self) -> bytes | None:
        return self.inbox.pop(0) if self.inbox else None

    _recv_frame_nowait = _recv_frame


def test_a_seq_minus_one_reply_answers_the_oldest_unanswered_request():
    conn = _Frames()
    stale = conn.send("step", action=0)  # times out below
    with pytest.raises(RemoteEnvError):
        conn.receive(stale, timeout=0.0)
    current = conn.send("step", action=1)
    conn.inbox = [
        protocol.pack(protocol.error_reply(-1, "protocol", "undecodable frame")),  # the stale one's
        protocol.pack({"seq": current, "ok": True, "obs": 1}),
    ]
    assert conn.receive(current)["obs"] == 1
    nxt = conn.send("step", action=1)
    conn.inbox = [protocol.pack(protocol.error_reply(-1, "protocol", "undecodable frame"))]
    with pytest.raises(RemoteEnvError, match="undecodable"):
        conn.receive(nxt)  # now it is the oldest unanswered one: its own


def test_an_unsendable_request_names_the_field_and_sends_nothing():
    conn = _Frames()
    with pytest.raises(RemoteEnvError, match="not sent \\(field 'options'\\)") as err:
        conn.send("reset", options={"x": np.broadcast_to(np.zeros(1, np.uint8), (LIMIT + 1,))})
    assert err.value.kind == "protocol" and str(LIMIT) in str(err.value)
    with pytest.raises(RemoteEnvError, match="field 'seed'"):
        conn.send("reset", seed=2**64)
    assert conn.sent == [] and not conn._unanswered
