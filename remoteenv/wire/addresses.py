"""ZeroMQ endpoints: which are private to this machine, and fresh ones for new sims. Both processes use it."""

from __future__ import annotations

import os
import re

_LOOPBACK = re.compile(r"^tcp://(127\.\d+\.\d+\.\d+|localhost|\[::1\])(:(\d+|\*))?$")


def is_loopback(address: str) -> bool:
    """True for ``ipc://`` endpoints and tcp endpoints on 127.0.0.0/8, localhost or [::1]."""
    return address.startswith("ipc://") or bool(_LOOPBACK.match(address))


def ipc_address(directory: str, instance: int) -> str:
    """An ipc endpoint for sim ``instance`` inside ``directory`` (a private temp dir)."""
    return f"ipc://{os.path.join(directory, f'sim-{instance}.sock')}"


def tcp_loopback_address() -> str:
    """A tcp endpoint on 127.0.0.1 whose port the OS assigns when the sim binds."""
    return "tcp://127.0.0.1:*"


def ipc_path(endpoint: str) -> str | None:
    """The socket file of an ipc endpoint, or None for other transports."""
    return endpoint[len("ipc://") :] if endpoint.startswith("ipc://") else None


#: What an env's ``transport=`` may be: the local pipe (the sim still binds
#: ipc for others to attach), or ZeroMQ over ipc or loopback tcp.
TRANSPORTS = ("pipe", "ipc", "tcp")


def zmq_transport(transport: str) -> str:
    """The ZeroMQ transport a sim binds for an env's ``transport=`` choice."""
    if transport not in TRANSPORTS:
        raise ValueError(f"transport must be one of {TRANSPORTS}, got {transport!r}")
    return "ipc" if transport == "pipe" else transport
