"""The agent's end of one sim connection, whatever carries its frames:
sequence numbers, stale replies, timeouts, error replies, a dead peer.

Runs in the agent process (the sim's ends are :mod:`remoteenv.sim.transport.channels`).
Every request gets a fresh sequence number; replies with another number are
stale (from a request that timed out) and are dropped. A request above the
wire's frame limit is refused before anything is sent. An error reply with
``seq`` -1 (the sim could not decode a frame) answers the oldest request
still unanswered on the connection: it is raised only when that is the one
being waited for, else dropped with that request. The transports are
subclasses: :class:`remoteenv.agent.connection.zmq_connection.ZmqConnection` and
:class:`remoteenv.agent.connection.pipe_connection.PipeConnection`.

Whatever the peer sends, a wait ends by its deadline: the deadline is checked
after every frame received, so stale or foreign frames arriving without end
cannot extend it, and :meth:`SimConnection.try_receive` reads at most
:data:`DRAIN_FRAMES` frames per call. Frames are decoded one at a time with
at most :data:`~remoteenv.wire.codec.frame_limits.MAX_REPLY_VALUES` values (counted
before any is built), and the text of an error reply is capped where it is
received.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.wire import protocol
from remoteenv.wire.wire_errors import ERROR_KINDS, short_repr

#: How often (seconds) a waiting call checks that the sim process still lives.
LIVENESS_CHECK_S = 0.1
#: Unanswered requests remembered per connection (to place ``seq`` -1 replies).
_MAX_UNANSWERED = 1024
#: Most frames one :meth:`SimConnection.try_receive` reads before it returns.
DRAIN_FRAMES = 64
#: Longest error ``kind`` shown as received (characters).
_MAX_KIND_CHARS = 64


class SimConnection:
    """Request/reply channel to one sim, whatever carries the frames.

    Subclasses implement the transport: ``_send_frame``, ``_recv_frame`` (wait
    up to :data:`LIVENESS_CHECK_S`), ``_recv_frame_nowait``, ``_after_timeout``,
    :meth:`reconnect`, :meth:`close` and :attr:`pollable`.

    Args:
        endpoint: where the sim is, named in error messages.
        instance: the sim's instance number, for error messages.
        timeout: default seconds to wait for a reply (None waits forever, but
            still notices a dead process).
        death_check: returns a description of why the sim process is gone,
            or None while it lives (or nobody can tell).
    """

    def __init__(
        self,
        endpoint: str,
        *,
        instance: int = 0,
        timeout: float | None = 60.0,
        death_check: Callable[[], str | None] | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.instance = instance
        self.timeout = timeout
        self.death_check = death_check
        self.closed = False
        self._seq = 0
        #: Requests sent and not yet answered, oldest first (a timed-out one stays
        #: until its late reply arrives or the transport is reset).
        self._unanswered: OrderedDict[int, None] = OrderedDict()

    # ------------------------------------------------------------ transport

    #: Whether a vector call waits for this transport's replies one connection
    #: at a time (:meth:`try_receive` with ``wait``) rather than polling them together.
    waits_in_turn = False

    @property
    def pollable(self) -> Any:
        """What to register in a ``zmq.Poller`` to learn that replies may be
        waiting (a ZeroMQ socket or a file descriptor); None if the transport
        cannot be polled, in which case a waiting caller asks :meth:`try_receive`."""
        return None

    def _send_frame(self, payload: bytes) -> None:
        raise NotImplementedError

    def _recv_frame(self) -> bytes | None:
        """The next frame, waiting up to :data:`LIVENESS_CHECK_S`; None if none came."""
        raise NotImplementedError

    def _recv_frame_nowait(self) -> bytes | None:
        raise NotImplementedError

    def _after_timeout(self) -> None:
        """Make the transport usable again after a reply did not come in time."""

    def reconnect(self) -> None:
        """Drop anything queued and start afresh (after a timeout)."""

    def close(self) -> None:
        self.closed = True

    # ------------------------------------------------------------ requests

    def send(self, cmd: str, **args: Any) -> int:
        """Send a request without waiting; returns its sequence number."""
        self._seq += 1
        args["seq"] = self._seq
        args["cmd"] = cmd
        if self.closed:
            raise RemoteEnvError(
                f"connection to sim instance {self.instance} is closed", kind="state", instance=self.instance
            )
        self._send_frame(self._encode(cmd, args))
        self._unanswered[self._seq] = None
        if len(self._unanswered) > _MAX_UNANSWERED:
            self._unanswered.popitem(last=False)
        return self._seq

    def _encode(self, cmd: str, args: dict[str, Any]) -> bytes:
        """``args`` as a frame; a clear error naming the field when it cannot be sent."""
        try:
            return protocol.pack(args)
        except (protocol.ProtocolError, ValueError, TypeError) as exc:
            field = next((k for k, v in args.items() if not _packable(v)), None)
            where = f" (field {field!r})" if field is not None else ""
            raise RemoteEnvError(
                f"'{cmd}' for sim instance {self.instance} was not sent{where}: {exc}. "
                "Nothing reached the sim; the env is still usable.",
                kind="protocol",
                instance=self.instance,
            ) from None

    def receive(self, seq: int, timeout: float | None = ..., what: str = "reply") -> dict[str, Any]:  # type: ignore[assignment]
        """Wait for the reply to request ``seq`` and return it.

        Raises :class:`RemoteEnvError` if the sim reports an error or its
        process dies, :class:`RemoteEnvTimeout` after ``timeout`` seconds.
        """
        if timeout is ...:
            timeout = self.timeout
        deadline = None if timeout is None else time.monotonic() + timeout
        stale = 0
        while True:
            frame = self._recv_frame()
            if frame is None:
                self._check_alive(what)
            else:
                reply = self._decode(frame, what)
                if self._answers(reply, seq):
                    break
                stale += 1  # a reply to an earlier, abandoned request (or a foreign frame): drop it
            if deadline is not None and time.monotonic() > deadline:
                self._time_out(what, timeout, stale)
        if reply.get("ok") is not True:
            self._raise(reply, what)
        return reply

    def request(self, cmd: str, timeout: float | None = ..., **args: Any) -> dict[str, Any]:  # type: ignore[assignment]
        """Send ``cmd`` and wait for its reply (see :meth:`receive`)."""
        return self.receive(self.send(cmd, **args), timeout, what=f"'{cmd}'")

    def try_receive(self, seq: int, what: str = "reply", wait: bool = False) -> dict[str, Any] | None:
        """The reply to request ``seq`` if it has arrived, else None; never
        blocks, or with ``wait`` waits up to :data:`LIVENESS_CHECK_S` for a frame.

        Drops stale replies (at most :data:`DRAIN_FRAMES` frames per call) and
        raises like :meth:`receive`. Lets a caller wait on many connections with
        one ``zmq.Poller`` on their :attr:`pollable`, or on each in turn.
        """
        for i in range(DRAIN_FRAMES):
            frame = self._recv_frame() if wait and i == 0 else self._recv_frame_nowait()
            if frame is None:
                return None
            reply = self._decode(frame, what)
            if self._answers(reply, seq):
                if reply.get("ok") is not True:
                    self._raise(reply, what)
                return reply
        return None  # a stream of stale frames: let the caller look at its deadline

    def check_alive(self, what: str = "a reply") -> None:
        """Raise :class:`remoteenv.SimDiedError` (kind ``"died"``) if the sim process is gone."""
        self._check_alive(what)

    # ------------------------------------------------------------ helpers

    def _answers(self, reply: dict[str, Any], seq: int) -> bool:
        """Whether ``reply`` answers request ``seq``; forgets the request it answers."""
        got = reply.get("seq")
        if got == -1 and not reply.get("ok", True):
            # An undecodable frame: the oldest unanswered request's, in order.
            got = next(iter(self._unanswered), seq)
        if isinstance(got, int):
            self._unanswered.pop(got, None)
        return got == seq

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

    def _time_out(self, what: str, timeout: float | None, stale: int) -> None:
        """Make the transport usable again and raise the timeout of a wait for ``what``."""
        why = self.why_silent()
        self._after_timeout()
        if why is None and stale:
            why = (
                f"{stale} frame(s) that answer no request of this call arrived meanwhile and were dropped "
                "(a broken or hostile server?)"
            )
        if why is None:
            why = "the process is alive but stuck or overloaded. Raise the env's timeout= or check the scene code"
        raise RemoteEnvTimeout(
            f"sim instance {self.instance} at {self.endpoint} did not answer {what} within {timeout:g} s; "
            f"{why}. A late reply will be dropped; the next call can go ahead.",
            kind="timeout",
            instance=self.instance,
        ) from None

    def why_silent(self) -> str | None:
        """What the transport saw that explains a missing reply (e.g. a connection
        dropped for an oversize frame) since it last looked, or None. Used in
        timeout messages (a vector call asks the first connection still pending)."""
        return None

    def _decode(self, frame: bytes, what: str) -> dict[str, Any]:
        """One received frame as a reply map (at most ``MAX_REPLY_VALUES`` values,
        counted before any is built); a ``protocol`` error naming ``what`` otherwise."""
        try:
            reply = protocol.unpack(frame, max_values=protocol.MAX_REPLY_VALUES, big_ints=True)
        except protocol.ProtocolError as exc:
            problem = str(exc)
        else:
            if isinstance(reply, dict):
                return reply
            problem = f"a {type(reply).__name__}, not a reply map"
        raise RemoteEnvError(
            f"sim instance {self.instance} at {self.endpoint} sent a frame the agent cannot use while it "
            f"waited for {what}: {problem}",
            kind="protocol",
            instance=self.instance,
        )

    def _raise(self, reply: dict[str, Any], what: str) -> None:
        """Raise the error a reply that is not ``ok: true`` carries (its text capped)."""
        err = reply.get("error")
        if reply.get("ok") is not False or not isinstance(err, dict):
            raise RemoteEnvError(
                f"sim instance {self.instance} at {self.endpoint} answered {what} with neither 'ok': true "
                f"nor an error map: {short_repr(reply, 120)}",
                kind="protocol",
                instance=self.instance,
            )
        sent = err.get("kind")
        # Only the spec's kinds pick an exception class: a server cannot pass
        # its error off as the agent's own "died" or "timeout".
        kind = sent if sent in ERROR_KINDS else "remote"
        shown = sent if isinstance(sent, str) and len(sent) <= _MAX_KIND_CHARS else short_repr(sent, _MAX_KIND_CHARS)
        message = _capped_text(err.get("message"), "unknown error")
        raise RemoteEnvError(
            f"sim instance {self.instance} failed {what} ({shown}): {message}",
            kind=kind,
            instance=self.instance,
            remote_traceback=_capped_text(err.get("traceback"), ""),
        )


def _capped_text(value: Any, default: str) -> str:
    """An error reply's text field as received, at most :data:`~remoteenv.wire.protocol.MAX_ERROR_CHARS` characters."""
    if not isinstance(value, str):
        return default if value is None else short_repr(value)
    limit = protocol.MAX_ERROR_CHARS
    return value if len(value) <= limit else f"{value[: limit - 40]}... ({len(value) - limit + 40} more characters)"


def _packable(value: Any) -> bool:
    try:
        protocol.pack(value)
    except (protocol.ProtocolError, ValueError, TypeError):
        return False
    return True


__all__ = ["DRAIN_FRAMES", "LIVENESS_CHECK_S", "SimConnection"]
