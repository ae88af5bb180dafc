"""The agent's end of one sim connection: requests, replies, timeouts, a dead peer.

Runs in the agent process. Every request gets a fresh sequence number;
replies with another number are stale (from a request that timed out) and
are dropped. Two transports carry the same frames:

- :class:`Connection`: a ZeroMQ DEALER socket to the sim's ROUTER. After a
  timeout the socket is thrown away and a new one connected, so the next call
  starts clean (the zguide's "Lazy Pirate" pattern).
- :class:`PipeConnection`: the launcher's end of the local pipe (a Unix
  socketpair, see :mod:`remoteenv.protocol`), for sims this process launched.
  No I/O threads sit between the two processes, and the sim's death shows at
  once as end of file.

:func:`connect_sim` picks the pipe when the sim has one.
"""

from __future__ import annotations

import select
import socket
import time
from collections import deque
from typing import Any, Callable

import zmq

from remoteenv.wire import protocol
from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.wire.hot_wait import HotWait, yield_cpu

#: How often (seconds) a waiting call checks that the sim process still lives.
LIVENESS_CHECK_S = 0.1
#: How long (seconds) to wait for a sim that closed its pipe to be reaped, so
#: that its exit code or signal can be reported.
_EXIT_REPORT_S = 2.0
_PIPE_READ_BYTES = 1 << 20
#: Longest busy-wait (seconds) for a reply on the local pipe (see :mod:`remoteenv.wire.hot_wait`).
AGENT_SPIN_S = 200e-6


class Connection:
    """Request/reply channel to one sim process over ZeroMQ.

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
        self._seq = 0
        self.socket: Any = None
        self._open()

    # ------------------------------------------------------------ transport (ZeroMQ)

    def _open(self) -> None:
        sock = zmq.Context.instance().socket(zmq.DEALER)
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

    @property
    def pollable(self) -> Any:
        """What to register in a ``zmq.Poller`` to learn that replies may be waiting."""
        return self.socket

    def _send_frame(self, payload: bytes) -> None:
        self.socket.send(payload, copy=True)

    def _recv_frame(self) -> bytes | None:
        """The next frame, waiting up to :data:`LIVENESS_CHECK_S`; None if none came."""
        try:
            return self.socket.recv(copy=True)
        except zmq.Again:
            return None

    def _recv_frame_nowait(self) -> bytes | None:
        try:
            return self.socket.recv(zmq.NOBLOCK, copy=True)
        except zmq.Again:
            return None

    def _after_timeout(self) -> None:
        self.reconnect()

    def reconnect(self) -> None:
        """Drop the socket (and anything queued on it) and connect afresh."""
        if self.socket is not None:
            self.socket.close(linger=0)
        self._open()

    def close(self) -> None:
        if self.socket is not None:
            self.socket.close(linger=0)
            self.socket = None

    # ------------------------------------------------------------ requests

    def send(self, cmd: str, **args: Any) -> int:
        """Send a request without waiting; returns its sequence number."""
        self._seq += 1
        args["seq"] = self._seq
        args["cmd"] = cmd
        if self.socket is None:
            raise RemoteEnvError(f"connection to sim instance {self.instance} is closed",
                                 kind="state", instance=self.instance)
        self._send_frame(protocol.pack(args))
        return self._seq

    def receive(self, seq: int, timeout: float | None = ..., what: str = "reply") -> dict[str, Any]:  # type: ignore[assignment]
        """Wait for the reply to request ``seq`` and return it.

        Raises :class:`RemoteEnvError` if the sim reports an error or its
        process dies, :class:`RemoteEnvTimeout` after ``timeout`` seconds.
        """
        if timeout is ...:
            timeout = self.timeout
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            frame = self._recv_frame()
            if frame is None:
                self._check_alive(what)
                if deadline is not None and time.monotonic() > deadline:
                    self._after_timeout()
                    raise RemoteEnvTimeout(
                        f"sim instance {self.instance} at {self.endpoint} did not answer "
                        f"{what} within {timeout:g} s; the process is alive but stuck or "
                        "overloaded. Raise the env's timeout= or check the scene code. "
                        "A late reply will be dropped; the next call can go ahead.",
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
        on many connections with one ``zmq.Poller`` on their :attr:`pollable`.
        """
        while True:
            frame = self._recv_frame_nowait()
            if frame is None:
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


class PipeConnection(Connection):
    """Request/reply channel to a sim this process launched, over its local pipe.

    Args:
        pipe: the launcher's end of the socketpair (:attr:`SimProcess.pipe`).
        endpoint: the sim's ZeroMQ endpoint, named in error messages only.
        instance, timeout, death_check: as for :class:`Connection`.
    """

    def __init__(
        self,
        pipe: socket.socket,
        *,
        endpoint: str = "",
        instance: int = 0,
        timeout: float | None = 60.0,
        death_check: Callable[[], str | None] | None = None,
    ) -> None:
        self.pipe = pipe
        self._decoder = protocol.StreamDecoder()
        self._frames: deque[bytes] = deque()
        self._eof = False
        self._hot = HotWait(AGENT_SPIN_S)
        super().__init__(endpoint or f"pipe fd {pipe.fileno()}", instance=instance,
                         timeout=timeout, death_check=death_check)

    def _open(self) -> None:
        self.pipe.setblocking(True)
        self._poll = select.poll()
        self._poll.register(self.pipe.fileno(), select.POLLIN)
        self.socket = self.pipe

    @property
    def pollable(self) -> Any:
        # zmq.Poller reports plain sockets by file descriptor.
        return self.pipe.fileno()

    def _send_frame(self, payload: bytes) -> None:
        try:
            self.pipe.sendall(protocol.stream_frame(payload))
        except OSError:
            # The sim is gone; as with ZeroMQ, the wait for the reply reports it.
            self._eof = True

    def _read(self, wait_s: float) -> None:
        """Move whatever has arrived (waiting up to ``wait_s``) into the frame queue."""
        if self._eof:
            self._check_alive("a reply", closed=True)
        if wait_s > 0 and not self._poll.poll(wait_s * 1000):
            return
        try:
            data = self.pipe.recv(_PIPE_READ_BYTES, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._eof = True
            self._check_alive("a reply", closed=True)
        try:
            self._frames.extend(self._decoder.feed(data))
        except protocol.ProtocolError as exc:
            raise RemoteEnvError(f"sim instance {self.instance} broke the pipe framing: {exc}",
                                 kind="protocol", instance=self.instance) from None

    def _recv_frame(self) -> bytes | None:
        if not self._frames and self._hot.worth_it():
            start = time.perf_counter()
            end = start + self._hot.window_s
            while not self._frames and time.perf_counter() < end:
                self._read(0.0)
                if not self._frames:
                    yield_cpu()  # let a peer that shares this CPU run
            if self._frames:
                self._hot.waited(time.perf_counter() - start)
                return self._frames.popleft()
            self._hot.waited(float("inf"))
        if not self._frames:
            self._read(LIVENESS_CHECK_S)
        return self._frames.popleft() if self._frames else None

    def _recv_frame_nowait(self) -> bytes | None:
        if not self._frames:
            self._read(0.0)
        return self._frames.popleft() if self._frames else None

    def _after_timeout(self) -> None:
        pass  # a stream has no stuck state: a late reply arrives later and is dropped by seq

    def reconnect(self) -> None:
        pass

    def close(self) -> None:
        # The pipe belongs to the launcher (SimProcess.pipe), which closes it.
        self.socket = None

    def _check_alive(self, what: str, closed: bool = False) -> None:
        if not closed:
            super()._check_alive(what)
            return
        # The sim closed its end: it is exiting. Give it a moment to be reaped
        # so the error can name its exit code or signal.
        why = None
        deadline = time.monotonic() + _EXIT_REPORT_S
        while self.death_check is not None and time.monotonic() < deadline:
            why = self.death_check()
            if why is not None:
                break
            time.sleep(0.01)
        raise RemoteEnvError(
            f"sim instance {self.instance} died while the agent waited for {what}: "
            f"{why or 'it closed its end of the local pipe'}",
            kind="died",
            instance=self.instance,
        )


def connect_sim(
    sim: Any,
    *,
    timeout: float | None = 60.0,
    curve_client_keypair: Any = None,
) -> Connection:
    """A connection to ``sim`` (a :class:`remoteenv.agent.launcher.SimProcess` or an
    attached sim): over its local pipe if it has one, else over ZeroMQ.
    ``curve_client_keypair`` is a :class:`remoteenv.wire.keys.KeyPair` (the
    launcher's :attr:`~remoteenv.agent.launcher.Launcher.curve_client_keypair`) or None."""
    death_check = getattr(sim, "death", None)
    pipe = getattr(sim, "pipe", None)
    if pipe is not None:
        return PipeConnection(pipe, endpoint=sim.endpoint or "", instance=sim.instance,
                              timeout=timeout, death_check=death_check)
    return Connection(
        sim.endpoint or "", instance=sim.instance, timeout=timeout, death_check=death_check,
        curve_server_key=getattr(sim, "curve_server_key", None),
        curve_client_keypair=None if curve_client_keypair is None
        else (curve_client_keypair.public, curve_client_keypair.secret),
    )
