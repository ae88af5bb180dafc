"""The wire format: arrays, scalars, spaces and malformed frames."""

from __future__ import annotations

import struct

import msgpack
import numpy as np
import pytest
from gymnasium import spaces

from remoteenv import protocol

DTYPES = [
    np.bool_,
    np.int8,
    np.int16,
    np.int32,
    np.int64,
    np.uint8,
    np.uint16,
    np.uint32,
    np.uint64,
    np.float16,
    np.float32,
    np.float64,
]
SHAPES = [(), (0,), (1,), (4,), (10,), (2, 3), (0, 5), (3, 0, 2), (480, 480, 3)]


def _sample(dtype, shape, rng):
    if np.dtype(dtype) == np.bool_:
        return rng.integers(0, 2, size=shape).astype(np.bool_)
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return rng.integers(info.min, info.max, size=shape, dtype=dtype, endpoint=True)
    return rng.standard_normal(size=shape).astype(dtype)


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: np.dtype(d).name)
@pytest.mark.parametrize("shape", SHAPES, ids=str)
def test_array_round_trip(dtype, shape):
    rng = np.random.default_rng(0)
    arr = _sample(dtype, shape, rng)
    frame = protocol.pack({"a": arr})
    first = protocol.unpack(frame)["a"]
    second = protocol.unpack(frame)["a"]
    assert first.dtype == np.dtype(dtype)
    assert first.shape == shape
    np.testing.assert_array_equal(first, arr)
    assert first.flags.writeable and first.flags.c_contiguous
    assert not np.shares_memory(first, arr)
    assert not np.shares_memory(first, second)
    if first.size:
        first.reshape(-1)[0] = first.reshape(-1)[-1]  # writable for real


def test_non_contiguous_and_big_endian_arrays():
    base = np.arange(24, dtype=np.float64).reshape(4, 6)
    view = base[:, ::2]
    out = protocol.unpack(protocol.pack(view))
    np.testing.assert_array_equal(out, view)
    big = np.arange(5, dtype=">i4")
    out = protocol.unpack(protocol.pack(big))
    assert out.dtype == np.dtype(np.int32)
    np.testing.assert_array_equal(out, big)


def test_numpy_scalars_become_python_values():
    msg = protocol.unpack(protocol.pack({"f": np.float32(1.5), "b": np.bool_(True), "i": np.int64(-3), "t": (1, 2)}))
    assert msg == {"f": 1.5, "b": True, "i": -3, "t": [1, 2]}
    assert type(msg["f"]) is float and type(msg["b"]) is bool and type(msg["i"]) is int


def test_unsendable_values_are_refused():
    with pytest.raises(TypeError):
        protocol.pack({"x": object()})
    with pytest.raises(TypeError):
        protocol.pack({"x": np.array(["a", "b"])})
    with pytest.raises(TypeError):
        protocol.pack({"x": np.array([object()], dtype=object)})


def _ext(dtype: str, shape, data: bytes, ndim: int | None = None) -> bytes:
    """An array extension frame built by hand (see the spec in protocol.py)."""
    name = dtype.encode()
    ndim = len(shape) if ndim is None else ndim
    head = bytes([len(name)]) + name + bytes([ndim]) + struct.pack(f"<{len(shape)}Q", *shape)
    return msgpack.packb(msgpack.ExtType(1, head + data))


def test_hand_built_array_frame_decodes():
    out = protocol.unpack(_ext("<f8", [2], np.array([1.5, -2.0]).tobytes()))
    np.testing.assert_array_equal(out, [1.5, -2.0])


@pytest.mark.parametrize(
    "frame",
    [
        b"\xc1",  # never-used msgpack byte
        msgpack.packb([1, 2, 3])[:-1],  # truncated
        msgpack.packb(msgpack.ExtType(7, b"x")),  # unknown extension
        _ext("|O", [1], b"\x00" * 8),  # object dtype
        _ext(">f8", [1], b"\x00" * 8),  # big-endian is not a wire dtype
        _ext("<f8", [2], b"\x00" * 8),  # size mismatch
        _ext("<f8", [2**40, 2**40], b""),  # huge declared size
        _ext("<f8", [1], b"\x00" * 8, ndim=40),  # too many dimensions
        _ext("<f8", [4], b"", ndim=4)[:-3],  # truncated shape
        msgpack.packb(msgpack.ExtType(1, b"")),  # empty payload
        msgpack.packb(msgpack.ExtType(1, b"\xff\xfe")),  # dtype length beyond the payload
    ],
)
def test_malformed_frames_raise_protocol_error(frame):
    with pytest.raises(protocol.ProtocolError):
        protocol.unpack(frame)


def test_stream_framing_splits_frames_at_any_chunking():
    frames = [protocol.pack({"seq": i, "a": np.arange(i)}) for i in range(5)] + [b""]
    stream = b"".join(protocol.stream_frame(f) for f in frames)
    for chunk in (1, 3, 7, len(stream)):
        decoder = protocol.StreamDecoder()
        out = []
        for i in range(0, len(stream), chunk):
            out += decoder.feed(stream[i : i + chunk])
        assert out == frames


def test_stream_framing_refuses_oversized_frames():
    with pytest.raises(protocol.ProtocolError):
        protocol.StreamDecoder().feed((protocol.MAX_MESSAGE_BYTES + 1).to_bytes(4, "little"))


def test_decode_request_checks_seq_and_cmd():
    assert protocol.decode_request(protocol.pack({"seq": 1, "cmd": "reset"}))["cmd"] == "reset"
    for bad in ({"cmd": "reset"}, {"seq": "1", "cmd": "reset"}, {"seq": True, "cmd": "x"}, {"seq": 1}, [1, "reset"]):
        with pytest.raises(protocol.ProtocolError):
            protocol.decode_request(protocol.pack(bad))


SPACES = [
    spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32),
    spaces.Box(np.array([-1.0, -np.inf]), np.array([2.0, np.inf]), dtype=np.float64),
    spaces.Box(0, 255, shape=(4, 4, 3), dtype=np.uint8),
    spaces.Discrete(2),
    spaces.Discrete(5, start=-2),
    spaces.MultiDiscrete([3, 4]),
    spaces.MultiBinary(6),
    spaces.MultiBinary([2, 3]),
    spaces.Dict({"pos": spaces.Box(-1, 1, (3,)), "mode": spaces.Discrete(3)}),
    spaces.Tuple((spaces.Discrete(2), spaces.Box(0, 1, (1,)))),
]


@pytest.mark.parametrize("space", SPACES, ids=lambda s: type(s).__name__)
def test_space_round_trip(space):
    rebuilt = protocol.space_from_wire(protocol.unpack(protocol.pack(protocol.space_to_wire(space))))
    assert rebuilt == space
    space.seed(0)
    for _ in range(5):
        sample = space.sample()
        assert rebuilt.contains(protocol.unpack(protocol.pack({"v": sample}))["v"])
