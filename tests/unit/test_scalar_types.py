"""numpy scalar types of reward and info values survive the wire via the 'types' map."""

from __future__ import annotations

import numpy as np

from remoteenv.wire import protocol
from remoteenv.wire.codec.scalar_types import describe_scalars, restore_scalars


def test_types_round_trip_through_the_codec() -> None:
    reply = {
        "obs": np.zeros(2),
        "reward": np.float64(-1.25),
        "info": {"ctrl": np.float32(-0.5), "n": np.int64(3), "ok": np.bool_(True), "plain": 2.0, "s": "x"},
    }
    back = restore_scalars(protocol.unpack(protocol.pack(describe_scalars(reply))))
    assert type(back["reward"]) is np.float64 and back["reward"] == -1.25
    info = back["info"]
    assert type(info["ctrl"]) is np.float32 and info["ctrl"] == np.float32(-0.5)
    assert type(info["n"]) is np.int64 and type(info["ok"]) is bool  # np.bool_ stays plain
    assert type(info["plain"]) is float and info["s"] == "x"
    assert "types" not in back


def test_plain_replies_carry_no_map() -> None:
    reply = describe_scalars({"obs": 1, "reward": 1.0, "info": {"a": 1}})
    assert "types" not in reply


def test_names_outside_the_spec_and_non_numbers_are_left_alone() -> None:
    reply = {"reward": 1.0, "info": {"a": "text", "b": 2}, "types": {"reward": "|O", "info": {"a": "<f4", "b": "xx"}}}
    back = restore_scalars(reply)
    assert back == {"reward": 1.0, "info": {"a": "text", "b": 2}}
    assert type(back["reward"]) is float and type(back["info"]["b"]) is int
