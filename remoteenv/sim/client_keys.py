"""The ZAP handler that admits only listed CURVE clients to a sim's socket.

Runs in the sim process.
"""

from __future__ import annotations

from typing import Any

import zmq


def start_client_key_check(ctx: zmq.Context[Any], client_keys: list[bytes]) -> Any:
    """Run a ZAP handler thread that admits only CURVE clients whose public key is listed."""
    from zmq.auth.thread import ThreadAuthenticator

    allowed = frozenset(bytes(k).strip() for k in client_keys)

    class _Allowed:
        def callback(self, domain: str, key: bytes) -> bool:
            return bytes(key) in allowed

    auth = ThreadAuthenticator(ctx)
    auth.start()
    auth.configure_curve_callback("*", credentials_provider=_Allowed())
    return auth
