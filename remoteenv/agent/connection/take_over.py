"""Taking a world over from a driver whose connection just ended.

Runs in the agent process. A sim frees a driven world when its socket
monitor reports the driver's disconnect, a moment after the close (see
"Drivers" in :mod:`remoteenv.wire.protocol`): an agent that attaches right
after the previous one closed may have its first reset refused for that
moment. :func:`request_taking_over` (one env) and the vector env's reset
resend such a refusal for up to
:data:`~remoteenv.wire.protocol.DRIVER_RELEASE_GRACE_S`, then raise it.
"""

from __future__ import annotations

import time
from typing import Any

from remoteenv.agent.connection.connect import SimConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import ANOTHER_DRIVER, STATE

#: Seconds between the resends of a refused reset.
RETRY_S = 0.02


def refused_for_another_driver(err: RemoteEnvError) -> bool:
    """Whether ``err`` is a sim's refusal because another connection drives the world."""
    return err.kind == STATE and ANOTHER_DRIVER in str(err)


def request_taking_over(conn: SimConnection, cmd: str, timeout: float | None, **args: Any) -> dict[str, Any]:
    """``conn.request(cmd, timeout, **args)``, resent while the sim refuses it
    because another connection drives the world, for up to
    :data:`~remoteenv.wire.protocol.DRIVER_RELEASE_GRACE_S` seconds (then the
    refusal, a :class:`remoteenv.StateError`, is raised)."""
    retry_until = time.monotonic() + protocol.DRIVER_RELEASE_GRACE_S
    while True:
        try:
            return conn.request(cmd, timeout=timeout, **args)
        except RemoteEnvError as err:
            if not refused_for_another_driver(err) or time.monotonic() >= retry_until:
                raise
        time.sleep(RETRY_S)


__all__ = ["RETRY_S", "refused_for_another_driver", "request_taking_over"]
