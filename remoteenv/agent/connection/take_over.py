"""Taking a world over from a driver whose connection just ended.

Runs in the agent process. A sim frees a driven world when its socket
monitor reports the driver's disconnect, a moment after the close (see
"Drivers" in :mod:`remoteenv.wire.protocol`): an agent that attaches right
after the previous one closed may have its first reset refused for that
moment. :func:`retry_taking_over` repeats such a reset (one env's request,
or a vector env's whole fan-out) for up to
:data:`~remoteenv.wire.protocol.DRIVER_RELEASE_GRACE_S`, then raises the refusal.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import ANOTHER_DRIVER, STATE

#: Seconds between the resends of a refused reset.
RETRY_S = 0.02

_T = TypeVar("_T")


def retry_taking_over(reset: Callable[[], _T]) -> _T:
    """``reset()``, called again while it raises the sim's refusal because another
    connection drives the world, for up to
    :data:`~remoteenv.wire.protocol.DRIVER_RELEASE_GRACE_S` seconds (then the
    refusal, a :class:`remoteenv.StateError`, is raised). Other errors are raised at once."""
    retry_until = time.monotonic() + protocol.DRIVER_RELEASE_GRACE_S
    while True:
        try:
            return reset()
        except RemoteEnvError as err:
            if err.kind != STATE or ANOTHER_DRIVER not in str(err) or time.monotonic() >= retry_until:
                raise
        time.sleep(RETRY_S)


__all__ = ["RETRY_S", "retry_taking_over"]
