"""Counting the msgpack values in a frame without building any of them.

Decoding is where a frame's size turns into memory: one byte of msgpack can
become a Python object of 60-90 bytes (an empty map, an empty list, a small
negative int), so a 32 MiB frame of such values decodes into some 2.4 GB. A
receiver that bounds its memory counts the values first
(:func:`values_within`) and refuses a frame that holds too many: the count
walks the headers only (strings, binaries and extension payloads are skipped
by their length), stops at the limit and costs a fraction of a microsecond
per value. Frames that are not valid msgpack are left to the decoder to refuse.

Both processes use it.
"""

from __future__ import annotations

import struct

_U16 = struct.Struct(">H").unpack_from
_U32 = struct.Struct(">I").unpack_from

#: Bytes taken by a value of a fixed-size type, by its first byte (the byte included).
_FIXED = {
    0xC0: 1,  # nil
    0xC2: 1,  # false
    0xC3: 1,  # true
    0xCA: 5,  # float 32
    0xCB: 9,  # float 64
    0xCC: 2,  # uint 8
    0xCD: 3,
    0xCE: 5,
    0xCF: 9,
    0xD0: 2,  # int 8
    0xD1: 3,
    0xD2: 5,
    0xD3: 9,
    0xD4: 3,  # fixext 1 (type byte + 1)
    0xD5: 4,
    0xD6: 6,
    0xD7: 10,
    0xD8: 18,
}
#: Types whose length follows the first byte: (bytes of the length, bytes before the payload).
_SIZED = {
    0xC4: (1, 2),  # bin 8
    0xC5: (2, 3),
    0xC6: (4, 5),
    0xC7: (1, 3),  # ext 8: length, then the type byte
    0xC8: (2, 4),
    0xC9: (4, 6),
    0xD9: (1, 2),  # str 8
    0xDA: (2, 3),
    0xDB: (4, 5),
}
#: Arrays and maps with a 16- or 32-bit count: (bytes of the count, values per entry).
_CONTAINERS = {0xDC: (2, 1), 0xDD: (4, 1), 0xDE: (2, 2), 0xDF: (4, 2)}


def _length(frame: bytes | memoryview, pos: int, size: int) -> int:
    if size == 1:
        return frame[pos]
    return int((_U16 if size == 2 else _U32)(frame, pos)[0])


def values_within(frame: bytes | memoryview, limit: int) -> bool:
    """Whether the msgpack document at the start of ``frame`` holds at most
    ``limit`` values (every container and every scalar counts one). Never
    builds a value; stops as soon as the count passes ``limit``. A frame cut
    short or holding a byte msgpack never uses counts as within the limit
    (the decoder refuses it)."""
    if len(frame) <= limit:
        return True  # every value takes one byte at least
    end = len(frame)
    pos = 0
    pending = 1
    count = 0
    try:
        while pending:
            if pos >= end:
                return True
            b = frame[pos]
            pending -= 1
            count += 1
            if count > limit:
                return False
            if b <= 0x7F or b >= 0xE0:  # positive and negative fixint
                pos += 1
            elif b <= 0x8F:  # fixmap
                pending += 2 * (b & 0x0F)
                pos += 1
            elif b <= 0x9F:  # fixarray
                pending += b & 0x0F
                pos += 1
            elif b <= 0xBF:  # fixstr
                pos += 1 + (b & 0x1F)
            elif b in _FIXED:
                pos += _FIXED[b]
            elif b in _SIZED:
                size, head = _SIZED[b]
                pos += head + _length(frame, pos + 1, size)
            elif b in _CONTAINERS:
                size, per_entry = _CONTAINERS[b]
                pending += per_entry * _length(frame, pos + 1, size)
                pos += 1 + size
            else:  # 0xC1: never used
                return True
    except (IndexError, struct.error):
        return True  # cut short
    return True


__all__ = ["values_within"]
