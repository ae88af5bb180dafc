"""A raw connection to the server under test, for one check.

The checker speaks the wire itself (a ZeroMQ DEALER socket, CURVE when the
launch-info file gives keys) rather than through the agent's connection
classes: it must send malformed frames, choose its own ``seq`` values and see
every reply, stale or not. Each check gets a fresh :class:`Probe`, so no
reply of one check can reach another. A handshake the server refused (it may
serve a bounded number of connections at once, and the previous check's may
not have ended there yet) is tried again after a short pause, as the agent's
connection does (:class:`~remoteenv.agent.connection.handshake_watch.HandshakeWatch`).

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

import zmq

from remoteenv.agent.connection.handshake_watch import HandshakeWatch
from remoteenv.compliance.failures import CheckFailed
from remoteenv.compliance.handshake_check import Handshake, parse_handshake
from remoteenv.compliance.values import envelope_problem
from remoteenv.wire import protocol
from remoteenv.wire.files.keys import KeyPair
from remoteenv.wire.wire_errors import refused_for_another_driver, short_repr

#: Frames from the server a probe's socket queues (libzmq stops reading beyond).
PROBE_RCVHWM = 4
#: Seconds between the resends of a reset refused because another connection drives the world.
RELEASE_RETRY_S = 0.02
#: Longest slice of a wait for a frame (seconds) before the probe looks at its handshakes.
LOOK_EVERY_S = 0.05


@dataclass(frozen=True)
class Target:
    """One server to check, and how to check it.

    Args:
        endpoint: the server's ZeroMQ endpoint.
        instance: its instance index in the launch-info file (for the report).
        curve_server_key: the server's Z85 public CURVE key; turns CURVE on.
        curve_client_keypair: client keys the server admits (default: a fresh pair).
        death_check: why the server's process is gone, or None while it runs or
            when that cannot be told (used after ``close``).
        timeout: seconds to wait for each reply.
        allow_close: let the ``close`` check stop the server.
        source: where the target came from (a launch-info path), for the report.
    """

    endpoint: str
    instance: int = 0
    curve_server_key: bytes | None = None
    curve_client_keypair: KeyPair | None = None
    death_check: Callable[[], str | None] | None = None
    timeout: float = 10.0
    allow_close: bool = False
    source: str = ""


def targets_from_launch_info(
    path: str | os.PathLike[str],
    instance: int | None = None,
    *,
    timeout: float = 10.0,
    allow_close: bool = False,
) -> list[Target]:
    """The servers a launch-info file names (all, or only ``instance``).

    Raises :class:`~remoteenv.agent.errors.RemoteEnvError` (kind ``"launch"``)
    if the file cannot be read or has no such instance.
    """
    from remoteenv.agent.launch.attach import AttachedSims

    sims = AttachedSims(path, None if instance is None else [instance])
    keys = sims.curve_client_keypair
    return [
        Target(
            endpoint=sim.endpoint,
            instance=sim.instance,
            curve_server_key=sim.curve_server_key,
            curve_client_keypair=keys,
            death_check=sim.death if sim.local and sim.pid is not None else None,
            timeout=timeout,
            allow_close=allow_close,
            source=os.fspath(path),
        )
        for sim in sims.sims
    ]


class Probe:
    """One check's DEALER connection to ``target``; use as a context manager.

    Sequence numbers increase strictly per probe, as the spec asks of clients.
    Every reply received is decoded and its envelope (``seq``, ``ok``,
    ``error``) checked against the spec; any problem raises
    :class:`CheckFailed`.
    """

    def __init__(self, target: Target) -> None:
        self.target = target
        self.timeout = target.timeout
        self._seq = 0
        self._handshake: Handshake | None = None
        sock: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
        sock.setsockopt(zmq.RCVHWM, PROBE_RCVHWM)  # a flooding server cannot fill the checker's memory
        if target.curve_server_key is not None:
            keys = target.curve_client_keypair
            public, secret = (keys.public, keys.secret) if keys is not None else zmq.curve_keypair()
            sock.curve_serverkey = target.curve_server_key
            sock.curve_publickey = public
            sock.curve_secretkey = secret
        self.watch = HandshakeWatch(sock, target.endpoint)
        sock.connect(target.endpoint)
        self.socket = sock

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.watch.close()
        self.socket.close(linger=0)

    # ------------------------------------------------------------ sending

    def next_seq(self, at_least: int = 0) -> int:
        """A fresh sequence number, larger than every earlier one and ``>= at_least``."""
        self._seq = max(self._seq + 1, at_least)
        return self._seq

    def send_frame(self, frame: bytes) -> None:
        """Send one raw frame (may be malformed on purpose)."""
        self.watch.send(frame)

    def send(self, cmd: str, *, min_seq: int = 0, **args: Any) -> int:
        """Send request ``cmd`` with ``args``; returns its fresh ``seq`` (at least ``min_seq``)."""
        seq = self.next_seq(min_seq)
        self.send_frame(protocol.pack({"seq": seq, "cmd": cmd, **args}))
        return seq

    # ------------------------------------------------------------ receiving

    def receive(self, what: str) -> dict[str, Any]:
        """The next reply, waiting up to the target's timeout; ``what`` names
        the awaited reply in failure messages."""
        if not self.frame_within(self.timeout):
            why = self.watch.why_failed()
            raise CheckFailed(f"no reply to {what} within {self.timeout:g} s" + (f"; {why}" if why else ""))
        frame = self.socket.recv(copy=True)
        try:
            reply = protocol.unpack(frame, max_values=protocol.MAX_REPLY_VALUES)
        except protocol.ProtocolError as exc:
            raise CheckFailed(f"the reply to {what} is not a frame of the spec: {exc}") from None
        problem = envelope_problem(reply)
        if problem:
            raise CheckFailed(f"the reply to {what}: {problem}")
        return reply

    def frame_within(self, seconds: float) -> bool:
        """Whether a frame arrives within ``seconds`` (left unread); a refused
        handshake is tried again meanwhile."""
        deadline = time.monotonic() + seconds
        while True:
            left = deadline - time.monotonic()
            if self.socket.poll(max(0, round(min(left, LOOK_EVERY_S) * 1000))):
                return True
            if left <= 0:
                return False
            self.watch.look()

    def silent(self, seconds: float, after: str) -> None:
        """Fail if any frame arrives within ``seconds`` (no reply is owed ``after`` something)."""
        if self.frame_within(seconds):
            frame = self.socket.recv(copy=True)
            raise CheckFailed(f"an unexpected frame arrived {after}: {short_repr(frame)}")

    def call(self, cmd: str, *, min_seq: int = 0, **args: Any) -> dict[str, Any]:
        """Send ``cmd`` and return its reply, which must echo the request's ``seq``
        (a fresh one, at least ``min_seq``).

        A ``reset`` or ``reset_batch`` refused because another connection drives
        the world is sent again (fresh ``seq``) for up to
        :data:`~remoteenv.wire.protocol.DRIVER_RELEASE_GRACE_S`, as the spec asks of a
        client taking a world over: the previous check's connection may have
        closed a moment before the server heard of it. The last reply is returned.
        """
        retry_until = time.monotonic() + protocol.DRIVER_RELEASE_GRACE_S
        while True:
            reply = self._call_once(cmd, min_seq, args)
            if cmd not in ("reset", "reset_batch") or not refused_for_another_driver(reply):
                return reply
            if time.monotonic() >= retry_until:
                return reply
            time.sleep(RELEASE_RETRY_S)

    def _call_once(self, cmd: str, min_seq: int, args: dict[str, Any]) -> dict[str, Any]:
        seq = self.send(cmd, min_seq=min_seq, **args)
        what = f"'{cmd}' (seq {seq})"
        reply = self.receive(what)
        if reply["seq"] != seq:
            detail = "" if reply["ok"] else f": {describe_error(reply)}"
            raise CheckFailed(f"the reply to {what} carries seq {reply['seq']}{detail}")
        return reply

    def ok(self, cmd: str, **args: Any) -> dict[str, Any]:
        """:meth:`call`, failing unless the reply is ``ok``."""
        reply = self.call(cmd, **args)
        if not reply["ok"]:
            raise CheckFailed(f"'{cmd}' failed: {describe_error(reply)}")
        return reply

    def error(self, cmd: str, kinds: Collection[str], why: str, **args: Any) -> dict[str, Any]:
        """:meth:`call`, failing unless the reply is an error of one of ``kinds``;
        returns the ``error`` map. ``why`` says what makes the request wrong."""
        reply = self.call(cmd, **args)
        if reply["ok"]:
            raise CheckFailed(
                f"'{cmd}' with {why} was answered ok; expected an error of kind {' or '.join(repr(k) for k in kinds)}"
            )
        error = reply["error"]
        if error["kind"] not in kinds:
            raise CheckFailed(
                f"'{cmd}' with {why} got error kind {error['kind']!r}, expected "
                f"{' or '.join(repr(k) for k in kinds)} ({short_repr(error['message'])})"
            )
        return error

    # ------------------------------------------------------------ handshake

    @property
    def handshake(self) -> Handshake:
        """The server's handshake on this connection (made on first use)."""
        if self._handshake is None:
            self._handshake = parse_handshake(self.ok("handshake", protocol=protocol.PROTOCOL_VERSION))
        return self._handshake

    def still_serving(self, after: str) -> None:
        """Fail unless a handshake on this connection is still answered ``ok``."""
        try:
            self.ok("handshake", protocol=protocol.PROTOCOL_VERSION)
        except CheckFailed as exc:
            raise CheckFailed(f"the server stopped serving after {after}: {exc}") from None

    def deadline(self) -> float:
        """``time.monotonic()`` value one reply timeout from now."""
        return time.monotonic() + self.timeout


def describe_error(reply: dict[str, Any]) -> str:
    """``kind: message`` of an error reply, bounded."""
    error = reply.get("error") or {}
    return f"{error.get('kind')!r}: {short_repr(error.get('message'))}"


__all__ = ["Probe", "Target", "describe_error", "targets_from_launch_info"]
