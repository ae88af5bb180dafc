"""Checks of the conversation itself: handshake, ``seq``, malformed frames, order.

None of them changes a world's state except :func:`stale_replies` (which
resets and steps world 0).

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

import re
import struct

import msgpack

from remoteenv.compliance.check_results import Check
from remoteenv.compliance.failures import CheckFailed, fail_unless
from remoteenv.compliance.probe import Probe
from remoteenv.compliance.probe_actions import neutral_action
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import PROTOCOL
from remoteenv.wire.wire_errors import short_repr as _short

#: A protocol version no server speaks.
ALIEN_VERSION = 999


def handshake(p: Probe) -> str:
    hs = p.handshake
    fail_unless(
        hs.protocol == protocol.PROTOCOL_VERSION,
        f"the server accepted protocol {protocol.PROTOCOL_VERSION} but its reply says protocol {hs.protocol}",
    )
    return f"{hs.env_id}: {hs.mode}, {hs.num_worlds} world(s)"


def version_refusal(p: Probe) -> None:
    ours = p.handshake.protocol
    error = p.error("handshake", [PROTOCOL], f"protocol {ALIEN_VERSION}", protocol=ALIEN_VERSION)
    message = error["message"]
    fail_unless(
        str(ALIEN_VERSION) in message,
        f"the refusal does not name the agent's version {ALIEN_VERSION}: {_short(message)}",
    )
    fail_unless(
        re.search(rf"(?<!\d){ours}(?!\d)", message),
        f"the refusal does not name the server's version {ours}: {_short(message)}",
    )
    p.still_serving("a refused handshake")


def seq_echo(p: Probe) -> None:
    # Increasing, as the spec asks of clients; beyond 32 bits and beyond a double's 53.
    for low, cmd in ((2**31 + 7, "handshake"), (2**53 + 1, "no_such_command"), (2**63 - 1, "handshake")):
        p.call(cmd, min_seq=low, protocol=protocol.PROTOCOL_VERSION)


def _expect_undecodable(p: Probe, frame: bytes, label: str) -> None:
    p.send_frame(frame)
    reply = p.receive(f"{label}")
    fail_unless(not reply["ok"], f"{label} was answered ok")
    fail_unless(reply["seq"] == -1, f"the error reply to {label} carries seq {reply['seq']}, the spec says -1")
    kind = reply["error"]["kind"]
    fail_unless(kind == PROTOCOL, f"{label} got error kind {kind!r}, expected 'protocol'")


def garbage_frames(p: Probe) -> None:
    request = protocol.pack({"seq": 1, "cmd": "handshake", "protocol": protocol.PROTOCOL_VERSION})
    for frame, label in (
        (b"\xc1\x00 not msgpack", "a frame of garbage bytes"),
        (b"", "an empty frame"),
        (request[:-3], "a truncated msgpack map"),
    ):
        _expect_undecodable(p, frame, label)
    p.still_serving("garbage frames")


def non_map_requests(p: Probe) -> None:
    for value, label in (([1, 2, 3], "a list"), ("handshake", "a str"), (None, "nil"), (42, "an int")):
        _expect_undecodable(p, msgpack.packb(value), f"a request that is {label}")
    p.still_serving("requests that are not maps")


def missing_seq_or_cmd(p: Probe) -> None:
    version = protocol.PROTOCOL_VERSION
    for request, label in (
        ({"cmd": "handshake", "protocol": version}, "a request without seq"),
        ({"seq": "7", "cmd": "handshake", "protocol": version}, "a request whose seq is a str"),
        ({"seq": True, "cmd": "handshake", "protocol": version}, "a request whose seq is a bool"),
        ({"seq": p.next_seq(), "protocol": version}, "a request without cmd"),
        ({"seq": p.next_seq(), "cmd": 5, "protocol": version}, "a request whose cmd is an int"),
    ):
        _expect_undecodable(p, msgpack.packb(request), label)
    p.still_serving("requests without seq or cmd")


def _array_ext(dtype: str, shape: tuple[int, ...], data: bytes, code: int = 1) -> msgpack.ExtType:
    """An array extension value built by hand, as the spec lays it out."""
    name = dtype.encode("ascii")
    head = bytes([len(name)]) + name + bytes([len(shape)]) + struct.pack(f"<{len(shape)}Q", *shape)
    return msgpack.ExtType(code, head + data)


def malformed_arrays(p: Probe) -> None:
    cases = (
        (_array_ext("<f4", (4,), b"\x00" * 12), "an array whose data is shorter than its shape"),
        (_array_ext("<f4", (2,), b"\x00" * 12), "an array whose data is longer than its shape"),
        (_array_ext("<c8", (1,), b"\x00" * 8), "an array of dtype <c8 (not in the spec's list)"),
        (_array_ext(">f4", (1,), b"\x00" * 4), "an array of big-endian dtype >f4"),
        (_array_ext("<f4", (1,) * 33, b"\x00" * 4), "an array of 33 dimensions"),
        (msgpack.ExtType(1, b"\x03<f"), "an array with a truncated header"),
        (msgpack.ExtType(7, b"\x00"), "an unknown extension type 7"),
    )
    for ext, label in cases:
        frame = msgpack.packb({"seq": p.next_seq(), "cmd": "step", "world": 0, "action": ext})
        _expect_undecodable(p, frame, f"a step request holding {label}")
    p.still_serving("malformed arrays")


def unknown_command(p: Probe) -> None:
    p.error("no_such_command", [PROTOCOL], "an unknown command name")
    p.still_serving("an unknown command")


def stale_replies(p: Probe) -> None:
    hs = p.handshake
    action = neutral_action(hs.action_space)
    sent = [
        ("handshake", p.send("handshake", protocol=protocol.PROTOCOL_VERSION)),
        ("no_such_command", p.send("no_such_command")),
        ("reset", p.send("reset", world=0, seed=0, options=None)),
        ("step", p.send("step", world=0, action=action)),
    ]
    for i, (cmd, seq) in enumerate(sent):
        reply = p.receive(f"request {i + 1} of 4 sent back to back ('{cmd}', seq {seq})")
        if reply["seq"] != seq:
            order = ", ".join(f"{c} (seq {s})" for c, s in sent)
            raise CheckFailed(
                f"requests {order} were sent back to back; reply {i + 1} carries seq "
                f"{reply['seq']}, expected {seq} (each reply its own seq, in order)"
            )
        fail_unless(
            reply["ok"] == (cmd != "no_such_command"), f"back to back, '{cmd}' (seq {seq}) got ok={reply['ok']}"
        )
    p.silent(0.3, "after the four replies to four requests")


CHECKS = (
    Check("handshake", "the handshake reply has the spec's fields and types", handshake),
    Check("version_refusal", "a handshake for protocol 999 is refused naming both versions", version_refusal),
    Check("seq_echo", "replies echo seq values beyond 32 and 53 bits", seq_echo),
    Check("garbage_frames", "undecodable frames get a 'protocol' error with seq -1", garbage_frames),
    Check("non_map_requests", "requests that are not maps get a 'protocol' error with seq -1", non_map_requests),
    Check(
        "missing_seq_or_cmd",
        "maps without an int seq or a str cmd get a 'protocol' error with seq -1",
        missing_seq_or_cmd,
    ),
    Check("malformed_arrays", "off-spec array extensions get a 'protocol' error with seq -1", malformed_arrays),
    Check("unknown_command", "an unknown command gets a 'protocol' error echoing its seq", unknown_command),
    Check("stale_replies", "back-to-back requests get one reply each, with their own seq, in order", stale_replies),
)
