"""The wire's size limits (part of the spec in :mod:`remoteenv.wire.protocol`)
and the error for a frame above them.

Both processes use it.
"""

from __future__ import annotations

from remoteenv.wire.wire_errors import ProtocolError

#: Largest frame either side sends or accepts (bytes), on ZeroMQ and on the pipe.
MAX_MESSAGE_BYTES = 32 * 1024 * 1024
#: Most entries of one msgpack array or map inside a request.
MAX_REQUEST_ITEMS = 1 << 20
#: Most msgpack values (of any type, containers included) one reply frame may
#: hold; a client refuses a larger reply before decoding it. A frame of at
#: most this many bytes cannot exceed it (every value takes a byte at least).
MAX_REPLY_VALUES = 1 << 20
#: Longest ``message`` of an error reply (characters); the traceback is capped alike.
MAX_ERROR_CHARS = 4000
#: Most worlds one sim process may host (a handshake's ``num_worlds``).
MAX_WORLDS = 1 << 16
#: Most spaces in one space map of a handshake (every Dict and Tuple member
#: counts, the outermost space included).
MAX_SPACE_NODES = 1024
#: Deepest nesting of Dict and Tuple spaces (a space without members has depth 1).
MAX_SPACE_DEPTH = 16


class FrameTooLarge(ProtocolError):
    """A frame (or a value in it) is above :data:`MAX_MESSAGE_BYTES`; nothing was sent."""

    def __init__(self, size: int, what: str = "a frame") -> None:
        super().__init__(
            f"{what} of {size} bytes is above the wire's frame limit of {MAX_MESSAGE_BYTES} bytes "
            f"({MAX_MESSAGE_BYTES >> 20} MiB, remoteenv.wire.protocol.MAX_MESSAGE_BYTES)"
        )
        self.size = size
