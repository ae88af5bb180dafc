"""The agent's end of one sim connection: requests, replies, timeouts, a dead peer.

Runs in the agent process. One DEALER socket talks to one sim's ROUTER.
Every request gets a fresh sequence number; replies with another number are
stale (from a request that timed out) and are dropped. After a timeout the
socket is thrown away and a new one connected, so the next call starts clean
(the zguide's "Lazy Pirate" pattern).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import zmq

from remoteenv import protocol
from remoteenv.errors import RemoteEnvError, RemoteEnvTimeout

#: How often (seconds) a waiting call checks that the sim process still lives.
LIVENESS_CHECK_S = 0.1


class Connection:
    """Request/reply channel to one sim process.

    Args:
        endpoint: the sim's bound ZeroMQ endpoint.
        instance: the sim's instance index, for error messages.
        timeout: default seconds to wait for a reply (None waits forever, but
            still notices a dead process).
        death_check: returns a description of why the sim process is gone,
            or None while it lives. None if there is no local process to watch.
        curve_server_key: the sim's public Z85 CURVE key; enables encryption.
        curve_client_keypair: ``(public, secret)`` Z85 client keys the sim
            admits; default a fresh pair (enough for a sim that admits any client).
    """

    def __init__(
        self,
        endpoint: str,
        *,
        instance: int = 0,
        timeout: float | None = 60.0,
        death_check: Callable[[], str | None] | None = None,
        curve_server_key: bytes | None = None,
        curve_client_keypair: tuple[bytes, bytes] | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.instance = instance
        self.timeout = timeout
        self.death_check = death_check
        self.curve_server_key = curve_server_key
        self.curve_client_keypair = curve_client_keypair
        self._ctx = zmq.Context.instance()
        self._seq = 0
        self.socket: zmq.Socket | None = None
        self._connect()

    def _connect(self) -> None:
        sock = self._ctx.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RECONNECT_IVL, 20)
        sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
        sock.setsockopt(zmq.RCVTIMEO, int(LIVENESS_CHECK_S * 1000))
        if self.curve_server_key is not None:
            public, secret = self.curve_client_keypair or zmq.curve_keypair()
            sock.curve_serverkey = self.curve_server_key
            sock.curve_publickey = public
            sock.curve_secretkey = secret
        sock.connect(self.endpoint)
        self.socket = sock

    def reconnect(self) -> None:
        """Drop the socket (and anything queued on it) and connect afresh."""
        if self.socket is not None:
            self.socket.close(linger=0)
        self._connect()

    # ------------------------------------------------------------ requests

    def send(self, cmd: str, **args: Any) -> int:
        """Send a request without waiting; returns its sequence number."""
        self._seq += 1
        args["seq"] = self._seq
        args["cmd"] = cmd
        assert self.socket is not None
        self.socket.send(protocol.pack(args), copy=True)
        return self._seq

    def receive(self, seq: int, timeout: float | None = ..., what: str = "reply") -> dict[str, Any]:  # type: ignore[assignment]
        """Wait for the reply to request ``seq`` and return it.

        Raises :class:`RemoteEnvError` if the sim reports an error or its
        process dies, :class:`RemoteEnvTimeout` after ``timeout`` seconds.
        """
        if timeout is ...:
            timeout = self.timeout
        deadline = None if timeout is None else time.monotonic() + timeout
        sock = self.socket
        assert sock is not None
        while True:
            try:
                frame = sock.recv(copy=True)
            except zmq.Again:
                self._check_alive(what)
                if deadline is not None and time.monotonic() > deadline:
                    self.reconnect()
                    raise RemoteEnvTimeout(
                        f"sim instance {self.instance} at {self.endpoint} did not answer "
                        f"{what} within {timeout:g} s; the process is alive but stuck or "
                        "overloaded. Raise the env's timeout= or check the scene code. "
                        "The connection was rebuilt; the next call can go ahead.",
                        kind="timeout",
                        instance=self.instance,
                    ) from None
                continue
            reply = self._decode(frame)
            if reply.get("seq") == seq:
                break
            if reply.get("seq") == -1 and not reply.get("ok", True):
                self._raise(reply, what)
            # A stale reply to an earlier, abandoned request: drop it.
        if not reply.get("ok"):
            self._raise(reply, what)
        return reply

    def request(self, cmd: str, timeout: float | None = ..., **args: Any) -> dict[str, Any]:  # type: ignore[assignment]
        """Send ``cmd`` and wait for its reply (see :meth:`receive`)."""
        return self.receive(self.send(cmd, **args), timeout, what=f"'{cmd}'")

    def try_receive(self, seq: int, what: str = "reply") -> dict[str, Any] | None:
        """The reply to request ``seq`` if it has arrived, else None; never blocks.

        Drops stale replies and raises like :meth:`receive`. Lets a caller wait
        on many connections with one ``zmq.Poller`` on their :attr:`socket`.
        """
        sock = self.socket
        assert sock is not None
        while True:
            try:
                frame = sock.recv(zmq.NOBLOCK, copy=True)
            except zmq.Again:
                return None
            reply = self._decode(frame)
            if reply.get("seq") == seq:
                if not reply.get("ok"):
                    self._raise(reply, what)
                return reply
            if reply.get("seq") == -1 and not reply.get("ok", True):
                self._raise(reply, what)

    def check_alive(self, what: str = "a reply") -> None:
        """Raise :class:`RemoteEnvError` (kind ``"died"``) if the sim process is gone."""
        self._check_alive(what)

    def close(self) -> None:
        if self.socket is not None:
            self.socket.close(linger=0)
            self.socket = None

    # ------------------------------------------------------------ helpers

    def _check_alive(self, what: str) -> None:
        if self.death_check is None:
            return
        why = self.death_check()
        if why is not None:
            raise RemoteEnvError(
                f"sim instance {self.instance} died while the agent waited for {what}: {why}",
                kind="died",
                instance=self.instance,
            )

    def _decode(self, frame: bytes) -> dict[str, Any]:
        try:
            reply = protocol.unpack(frame)
        except protocol.ProtocolError as exc:
            raise RemoteEnvError(
                f"sim instance {self.instance} sent an undecodable reply: {exc}",
                kind="protocol",
                instance=self.instance,
            ) from None
        if not isinstance(reply, dict):
            raise RemoteEnvError(
                f"sim instance {self.instance} sent a reply that is not a map",
                kind="protocol",
                instance=self.instance,
            )
        return reply

    def _raise(self, reply: dict[str, Any], what: str) -> None:
        err = reply.get("error") or {}
        kind = str(err.get("kind", "remote"))
        message = str(err.get("message", "unknown error"))
        raise RemoteEnvError(
            f"sim instance {self.instance} failed {what} ({kind}): {message}",
            kind=kind,
            instance=self.instance,
            remote_traceback=str(err.get("traceback", "")),
        )
