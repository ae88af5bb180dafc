"""The wire's size limits (part of the spec in :mod:`remoteenv.wire.protocol`)
and the error for a frame above them."""

from __future__ import annotations

from remoteenv.wire.errors import ProtocolError

#: Largest frame either side sends or accepts (bytes), on ZeroMQ and on the pipe.
MAX_MESSAGE_BYTES = 32 * 1024 * 1024
#: Most entries of one msgpack array or map inside a request.
MAX_REQUEST_ITEMS = 1 << 20
#: Longest ``message`` of an error reply (characters); the traceback is capped alike.
MAX_ERROR_CHARS = 4000


class FrameTooLarge(ProtocolError):
    """A frame (or a value in it) is above :data:`MAX_MESSAGE_BYTES`; nothing was sent."""

    def __init__(self, size: int, what: str = "a frame") -> None:
        super().__init__(
            f"{what} of {size} bytes is above the wire's frame limit of {MAX_MESSAGE_BYTES} bytes "
            f"({MAX_MESSAGE_BYTES >> 20} MiB, remoteenv.wire.protocol.MAX_MESSAGE_BYTES)"
        )
        self.size = size
