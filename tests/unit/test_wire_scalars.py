"""numpy scalars keep their type on the wire (msgpack extension type 2)."""

from __future__ import annotations

from collections import OrderedDict
from enum import IntEnum

import numpy as np
import pytest

from remoteenv.wire import protocol
from remoteenv.wire.errors import ProtocolError


@pytest.mark.parametrize(
    "value",
    [np.float32(1.5), np.float64(-2.25), np.int64(7), np.int32(-3), np.uint8(200), np.bool_(True), np.float16(0.5)],
)
def test_numpy_scalars_round_trip_with_their_type(value: np.generic) -> None:
    back = protocol.unpack(protocol.pack({"v": value}))["v"]
    assert type(back) is type(value)
    assert back == value


def test_plain_values_stay_plain() -> None:
    class Level(IntEnum):
        HIGH = 2

    doc = {"f": 1.5, "i": 3, "b": True, "t": (1, 2), "m": OrderedDict(a=1), "e": Level.HIGH}
    back = protocol.unpack(protocol.pack(doc))
    assert back == {"f": 1.5, "i": 3, "b": True, "t": [1, 2], "m": {"a": 1}, "e": 2}
    assert type(back["f"]) is float and type(back["b"]) is bool and type(back["e"]) is int


def test_a_malformed_scalar_is_a_protocol_error() -> None:
    import msgpack

    bad = msgpack.packb({"v": msgpack.ExtType(2, b"\x03<f8" + b"\x00" * 3)})
    with pytest.raises(ProtocolError, match="needs 8 bytes"):
        protocol.unpack(bad)
    bad = msgpack.packb({"v": msgpack.ExtType(2, b"\x02|O" + b"\x00" * 8)})
    with pytest.raises(ProtocolError, match="not allowed"):
        protocol.unpack(bad)
