"""The frame stream's credit messages: what a publisher accepts and what it drops."""

from __future__ import annotations

import msgpack
import pytest

from remoteenv.wire.messages.stream_credit import (
    WINDOW,
    credit_message,
    is_superseded,
    parse_credit,
    superseded_message,
)


def test_a_reader_grants_what_a_publisher_takes() -> None:
    for n in (1, WINDOW):
        assert parse_credit(credit_message(n)) == n
    with pytest.raises(ValueError):
        credit_message(WINDOW + 1)


@pytest.mark.parametrize(
    "frame",
    [
        msgpack.packb({"credit": 0}),
        msgpack.packb({"credit": WINDOW + 1}),
        msgpack.packb({"credit": -3}),
        msgpack.packb({"credit": True}),
        msgpack.packb({"credit": 2.0}),
        msgpack.packb({"credit": 2, "more": 1}),
        msgpack.packb([2]),
        b"\xc1",  # never valid msgpack
        msgpack.packb({"credit": 1, "pad": "x" * 100}),  # over the size bound
    ],
)
def test_anything_else_is_dropped(frame: bytes) -> None:
    assert parse_credit(frame) is None


def test_superseded_notice() -> None:
    assert is_superseded(msgpack.unpackb(superseded_message()))
    assert not is_superseded({"index": 0, "frame": b""})
