"""The remoteenv wire format. This path is kept for users; the spec lives in
:mod:`remoteenv.wire.protocol`, the space codec in :mod:`remoteenv.wire.codec.spaces`.

Both processes speak the spec; this face is for users' code.
"""

from remoteenv.wire.codec.spaces import space_from_wire, space_to_wire
from remoteenv.wire.protocol import *  # noqa: F403
from remoteenv.wire.protocol import __all__ as _protocol_all

__all__ = [*_protocol_all, "space_from_wire", "space_to_wire"]
