"""Issue 28, item 6: an integer beyond msgpack's range crosses the wire in a
reply (extension type 2: Gymnasium's 128-bit ``np_random_seed``), and only there."""

from __future__ import annotations

import msgpack
import pytest

from remoteenv.wire import protocol
from remoteenv.wire.codec.arrays import MAX_BIG_INT_BYTES


@pytest.mark.parametrize("value", [2**64, 2**127 + 12345, -(2**63) - 1, -(2**200), 2**511 - 1, -(2**511)])
def test_a_reply_carries_a_big_integer_faithfully(value):
    reply = {"seq": 1, "ok": True, "value": [value, 3, -4]}
    assert protocol.unpack(protocol.pack(reply, big_ints=True), big_ints=True) == reply


def test_ordinary_integers_are_encoded_as_before():
    reply = {"seq": 1, "ok": True, "value": [0, -(2**63), 2**64 - 1]}
    assert protocol.pack(reply, big_ints=True) == protocol.pack(reply)


def test_a_request_keeps_the_range_and_a_sim_refuses_the_extension():
    with pytest.raises(ValueError, match="outside the wire's range"):
        protocol.pack({"seq": 1, "cmd": "reset", "seed": 2**64})
    frame = protocol.pack({"seq": 1, "value": 2**70}, big_ints=True)
    with pytest.raises(protocol.ProtocolError, match="extension type 2"):
        protocol.unpack(frame)


def test_an_integer_too_long_is_refused_both_ways():
    with pytest.raises(ValueError, match="bits"):
        protocol.pack({"value": 2**600}, big_ints=True)
    frame = msgpack.packb({"value": msgpack.ExtType(2, b"\x01" * (MAX_BIG_INT_BYTES + 1))})
    with pytest.raises(protocol.ProtocolError, match="bytes"):
        protocol.unpack(frame, big_ints=True)
    with pytest.raises(protocol.ProtocolError, match="bytes"):
        protocol.unpack(msgpack.packb({"value": msgpack.ExtType(2, b"")}), big_ints=True)


def test_a_batch_with_an_integer_beyond_int64_in_its_infos_goes_as_maps():
    # Issue 35, item 6: a column is int64; before, 2**70 raised OverflowError in the sim's encoding.
    from remoteenv.wire.messages.batch_encoding import columnar_infos

    assert "columns" in columnar_infos([{"a": 2**63 - 1}, {"a": -(2**63)}])
    for big in (2**63, -(2**63) - 1, 2**70, 2**510):
        packed = columnar_infos([{"a": 1}, {"a": big}])
        assert packed == {"maps": [{"a": 1}, {"a": big}]}
        assert protocol.unpack(protocol.pack({"info": packed}, big_ints=True), big_ints=True)["info"] == packed
