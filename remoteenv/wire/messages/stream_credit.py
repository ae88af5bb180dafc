"""The frame stream's flow control, shared by its two ends.

A frame publisher (sim side, :mod:`remoteenv.sim.publisher`) sends items only
against *credit* its reader (agent side, :class:`remoteenv.integrations.frame_dataset.RemoteIterableDataset`)
grants: ``{"credit": n}`` in msgpack, ``1 <= n <=`` :data:`WINDOW`. A reader
never has more than :data:`WINDOW` items asked for and not yet read, so the
publisher renders at most that far ahead and a reader that asks for exactly
what it reads leaves nothing in flight.

The newest reader to grant credit is served; the one it replaces gets
``{"superseded": true}`` after the items already on their way to it, so
that two readers of one publisher are told apart instead of starving.
"""

from __future__ import annotations

from remoteenv.wire import protocol

#: Items a reader may have asked for and not yet received.
WINDOW = 8
#: Largest credit message a publisher accepts (bytes).
MAX_CREDIT_BYTES = 64


def credit_message(n: int) -> bytes:
    """The message granting ``n`` more items (``1 <= n <= WINDOW``)."""
    if not 1 <= n <= WINDOW:
        raise ValueError(f"credit must be in [1, {WINDOW}], got {n}")
    return protocol.pack({"credit": int(n)})


def superseded_message() -> bytes:
    """What a publisher sends the reader another one replaced."""
    return protocol.pack({"superseded": True})


def is_superseded(item: object) -> bool:
    """Whether a decoded message is :func:`superseded_message`'s."""
    return isinstance(item, dict) and item.get("superseded") is True


def parse_credit(frame: bytes) -> int | None:
    """The credit a message grants, or None for anything that is not
    ``{"credit": n}`` with an int ``1 <= n <= WINDOW``."""
    if len(frame) > MAX_CREDIT_BYTES:
        return None
    try:
        msg = protocol.unpack(frame)
    except protocol.ProtocolError:
        return None
    if not isinstance(msg, dict) or set(msg) != {"credit"}:
        return None
    credit = msg["credit"]
    if type(credit) is not int or not 1 <= credit <= WINDOW:
        return None
    return credit


__all__ = ["MAX_CREDIT_BYTES", "WINDOW", "credit_message", "is_superseded", "parse_credit", "superseded_message"]
