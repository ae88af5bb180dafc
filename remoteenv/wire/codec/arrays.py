"""numpy arrays on the wire: msgpack extension type 1 (the spec's "Values" in
:mod:`remoteenv.wire.protocol`). Encoding refuses dtypes off the list and arrays
above the frame limit before copying them; decoding checks the header against
the payload and returns a fresh, writable array that shares memory with nothing.

Both processes use it.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import msgpack
import numpy as np

from remoteenv.wire.codec.frame_limits import MAX_MESSAGE_BYTES, FrameTooLarge
from remoteenv.wire.wire_errors import ProtocolError, short_repr

_EXT_NDARRAY = 1
_EXT_BIG_INT = 2
#: Longest integer extension type 2 carries: 512 bits.
MAX_BIG_INT_BYTES = 64

#: The only dtypes that may appear on the wire.
ARRAY_DTYPES = frozenset(
    np.dtype(t).newbyteorder("<").str if np.dtype(t).itemsize > 1 else np.dtype(t).str
    for t in (
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
    )
)
_MAX_NDIM = 32


def wire_dtype(dtype: np.dtype) -> str:
    d = dtype.newbyteorder("<") if dtype.itemsize > 1 else dtype
    s = d.str
    if s not in ARRAY_DTYPES:
        raise TypeError(f"numpy dtype {dtype} cannot be sent; allowed: {sorted(ARRAY_DTYPES)}")
    return s


#: numpy dtype for each allowed wire dtype string (native byte order on decode).
_DTYPES = {t: np.dtype(t) for t in ARRAY_DTYPES}
_SHAPE_FORMATS = [struct.Struct(f"<{n}Q") for n in range(_MAX_NDIM + 1)]
#: Encoded array headers by (dtype string, shape); arrays of one shape recur every step.
_HEADERS: dict[tuple[str, tuple[int, ...]], bytes] = {}


def _array_header(dtype: str, shape: tuple[int, ...]) -> bytes:
    key = (dtype, shape)
    head = _HEADERS.get(key)
    if head is None:
        if len(shape) > _MAX_NDIM:
            raise TypeError(f"arrays of more than {_MAX_NDIM} dimensions cannot be sent")
        name = dtype.encode("ascii")
        head = bytes([len(name)]) + name + bytes([len(shape)]) + _SHAPE_FORMATS[len(shape)].pack(*shape)
        if len(_HEADERS) < 4096:
            _HEADERS[key] = head
    return head


def _default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        if obj.nbytes > MAX_MESSAGE_BYTES:  # refuse before copying it
            raise FrameTooLarge(obj.nbytes, "a numpy array")
        dtype = obj.dtype.str
        if dtype not in _DTYPES or not obj.flags.c_contiguous:
            dtype = wire_dtype(obj.dtype)
            obj = np.asarray(obj, dtype=_DTYPES[dtype], order="C")  # keeps 0-d arrays 0-d
        return msgpack.ExtType(_EXT_NDARRAY, _array_header(dtype, obj.shape) + obj.tobytes())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, (tuple, set, frozenset)):
        return list(obj)
    if isinstance(obj, int):  # msgpack hands over the ints it cannot hold
        raise ValueError(f"integer {short_repr(obj)} is outside the wire's range [-2**63, 2**64)")
    raise TypeError(f"cannot send a {type(obj).__name__} on the wire: {short_repr(obj)}")


def _default_big(obj: Any) -> Any:
    """:func:`_default`, and an int beyond msgpack's range as extension type 2 (replies only)."""
    if isinstance(obj, int) and not isinstance(obj, bool):
        size = ((obj if obj >= 0 else ~obj).bit_length() + 8) // 8  # two's complement, room for the sign bit
        if size > MAX_BIG_INT_BYTES:
            raise ValueError(f"integer {short_repr(obj)} has more than {8 * MAX_BIG_INT_BYTES} bits")
        return msgpack.ExtType(_EXT_BIG_INT, obj.to_bytes(size, "big", signed=True))
    return _default(obj)


def _ext_hook_big(code: int, data: bytes) -> Any:
    """:func:`_ext_hook`, and extension type 2's integers (replies only)."""
    if code == _EXT_BIG_INT:
        if not 0 < len(data) <= MAX_BIG_INT_BYTES:
            raise ProtocolError(f"an integer of {len(data)} bytes (1..{MAX_BIG_INT_BYTES} allowed)")
        return int.from_bytes(data, "big", signed=True)
    return _ext_hook(code, data)


def _ext_hook(code: int, data: bytes) -> Any:
    if code != _EXT_NDARRAY:
        raise ProtocolError(f"unknown msgpack extension type {code}")
    try:
        n = data[0]
        dtype = data[1 : 1 + n].decode("ascii")
        ndim = data[1 + n]
        offset = 2 + n
        shape = _SHAPE_FORMATS[ndim].unpack_from(data, offset)
    except (IndexError, UnicodeDecodeError, struct.error) as exc:
        raise ProtocolError(f"malformed array header: {exc}") from None
    dt = _DTYPES.get(dtype)
    if dt is None:
        raise ProtocolError(f"array dtype {dtype!r} is not allowed")
    offset += 8 * ndim
    count = math.prod(shape)
    if count * dt.itemsize != len(data) - offset:
        raise ProtocolError(
            f"array of dtype {dtype} and shape {list(shape)} needs {count * dt.itemsize} "
            f"bytes, got {len(data) - offset}"
        )
    # frombuffer aliases the frame and is read-only: copy into a fresh array.
    return np.frombuffer(data, dt, count, offset).reshape(shape).copy()
