"""The agent's end of the local pipe to a sim this process launched (the sim's
end is its :class:`~remoteenv.sim.transport.channels.PipeChannel`).

Runs in the agent process. A Unix socketpair carrying length-prefixed frames
(see :mod:`remoteenv.wire.protocol`): no I/O threads sit between the two
processes, and the sim's death shows at once as end of file. Waits for a
reply start hot while replies have been quick (:mod:`remoteenv.wire.shared_memory.hot_wait`;
a plain step's reply in the shared region on those replies' own history);
a wait that blocks for a reply in the shared region asks the sim for a
heads-up once its physics is done, and waits hot from it (the fast lane's
heads-up, :mod:`remoteenv.wire.shared_memory.doorbell`).
"""

from __future__ import annotations

import socket
import struct
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from remoteenv.agent.connection.region_watch import RegionWatch
from remoteenv.agent.connection.sim_connection import LIVENESS_CHECK_S, SimConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory.doorbell import Doorbell
from remoteenv.wire.shared_memory.hot_wait import HotWait

#: How long (seconds) to wait for a sim that closed its pipe to be reaped, so
#: that its exit code or signal can be reported.
_EXIT_REPORT_S = 2.0
#: Longest busy-wait (seconds) for a reply on the local pipe (see :mod:`remoteenv.wire.shared_memory.hot_wait`).
AGENT_SPIN_S = 200e-6
#: Longest busy-wait (seconds) for the reply to a plain step posted in the shared
#: region (every world steps, none resets first), on the history of those waits
#: alone: where the sims' physics threads take every CPU, an agent that waits
#: hot takes CPU time from them, which costs more than the wake-up it saves once
#: the wait is longer than about this (docs/performance-history.md, "Fewer kinds of numpy call, and
#: the lane's own wait").
LANE_SPIN_S = 500e-6
#: Longest busy-wait (seconds) for a reply after the sim's heads-up that it is
#: due (its physics done; the sim sends none where the rest of its tick takes
#: longer than :data:`~remoteenv.sim.transport.shared_lane_server.HEADS_UP_TAIL_S`).
HEADS_UP_WAIT_S = 1e-3


class PipeConnection(RegionWatch, SimConnection):
    """Request/reply channel to a sim this process launched, over its local pipe.

    A vector call waits for its pipes' replies in turn (:attr:`waits_in_turn`):
    one blocking read per reply is cheaper than polling them together.

    Args:
        pipe: the launcher's end of the socketpair (:attr:`SimProcess.pipe`).
        endpoint: the sim's ZeroMQ endpoint, named in error messages only.
        instance, timeout, death_check: as for :class:`SimConnection`.
        pid: the sim's process id, if known.
    """

    def __init__(
        self,
        pipe: socket.socket,
        *,
        endpoint: str = "",
        instance: int = 0,
        timeout: float | None = 60.0,
        death_check: Callable[[], str | None] | None = None,
        pid: int | None = None,
    ) -> None:
        #: The sim's process id (the region of ``shared_batch`` is read through it).
        self.pid = pid
        super().__init__(
            endpoint or f"pipe fd {pipe.fileno()}", instance=instance, timeout=timeout, death_check=death_check
        )
        self.pipe = pipe
        self._decoder = protocol.StreamDecoder()
        self._frames: deque[bytes] = deque()
        #: The request posted in the shared region whose reply is awaited there, and its doorbell.
        self._watch: tuple[int, Doorbell] | None = None
        #: That request is a plain step (its wait may be hot on :attr:`_lane_hot`).
        self._watch_plain = False
        #: Whether the watched request rang its sim (it slept: the wait includes its wake-up).
        self._watch_rang = False
        #: The request a wait is for (a region reply is taken only for its own request).
        self._awaiting = 0
        #: Replies to later requests that came while the awaited one's reply was due in
        #: the region (at most one per request in flight).
        self._held: dict[int, dict[str, Any]] = {}
        self._eof = False
        self._hot = HotWait(AGENT_SPIN_S)
        #: The hot wait for plain steps' region replies, on their own history (:data:`LANE_SPIN_S`).
        self._lane_hot = HotWait(LANE_SPIN_S)
        #: The hot wait after a heads-up (asked for only where waiting hot is allowed).
        self._soon = HotWait(HEADS_UP_WAIT_S)
        #: Heads-ups this connection was woken by (see :meth:`_after_heads_up`).
        self.heads_ups = 0
        pipe.setblocking(True)
        # A blocking read returns after at most LIVENESS_CHECK_S (one system
        # call per wait instead of a poll and a read).
        whole, frac = divmod(LIVENESS_CHECK_S, 1.0)
        pipe.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", int(whole), int(frac * 1e6)))

    waits_in_turn = True

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

    def _read(self, wait: bool) -> None:
        """Move whatever has arrived (with ``wait``: waiting up to
        :data:`LIVENESS_CHECK_S` for something) into the frame queue."""
        if not self._read_quietly(wait):
            self._check_alive("a reply", closed=True)

    def _read_quietly(self, wait: bool) -> bool:
        """:meth:`_read`, but False at the pipe's end (nothing raised: the wait that reports it is the caller's)."""
        if self._eof:
            return False
        data = self._decoder.recv_from(self.pipe, wait)
        if data is None:
            return True
        if not data:
            self._eof = True
            return False
        try:
            self._frames.extend(self._decoder.feed(data))
        except protocol.ProtocolError as exc:
            raise RemoteEnvError(
                f"sim instance {self.instance} broke the pipe framing: {exc}", kind="protocol", instance=self.instance
            ) from None
        return True

    def receive(self, seq: int, timeout: float | None = ..., what: str = "reply") -> dict[str, Any]:  # type: ignore[assignment]
        self._awaiting = seq
        return super().receive(seq, timeout, what)

    def try_receive(self, seq: int, what: str = "reply", wait: bool = False) -> dict[str, Any] | None:
        self._awaiting = seq
        return super().try_receive(seq, what, wait)

    def _answers(self, reply: dict[str, Any], seq: int) -> bool:
        if protocol.is_reply_soon(reply):  # read after its wait: it answers nothing
            return False
        got = reply.get("seq")
        if type(got) is int and got > seq and got in self._unanswered:
            # A later request's reply read before the awaited one was seen in the region
            # (the sim answered in order): kept for its own wait.
            self._held[got] = reply
            return False
        return super()._answers(reply, seq)

    def _take_held(self) -> dict[str, Any] | None:
        held = self._held
        if not held:
            return None
        reply = held.pop(self._awaiting, None)
        for seq in [s for s in held if s < self._awaiting]:  # their requests were abandoned
            del held[seq]
        if reply is not None and self._watch is not None and self._watch[0] == self._awaiting:
            self._watch = None  # answered on the pipe
        return reply

    def _decode(self, frame: Any, what: str) -> dict[str, Any]:
        if isinstance(frame, dict):  # a reply found in the region, or held
            return frame
        reply = super()._decode(frame, what)
        # A heads-up read here (it came late, after the wait it was for) answers
        # nothing: the reply may still come in the region, so the watch goes on.
        if self._watch is not None and reply.get("seq") == self._watch[0] and not protocol.is_reply_soon(reply):
            self._watch = None
        return reply

    # ------------------------------------------------------------ frames

    def _recv_frame(self) -> Any:
        region = self._region_reply() or self._take_held()
        if region is not None:
            return region
        # A plain step's region reply is waited for on its own history: a frame
        # (an announcement, an error) and a step with resets do not count there.
        lane = self._watch_plain and self._watch is not None and self._watch[0] == self._awaiting
        hot = self._lane_hot if lane else self._hot
        if not self._frames and hot.worth_it():
            start = time.perf_counter()
            self._read(False)
            while not self._frames and hot.spin():
                region = self._region_reply()
                if region is not None:
                    hot.waited(time.perf_counter() - start)
                    return region
                self._read(False)
            if self._frames:
                if not lane:
                    hot.waited(time.perf_counter() - start)
                return self._frames.popleft()
            if not (lane and self._watch_rang):  # a sim woken first says nothing of the lane's pace
                hot.waited(float("inf"))
        if not self._frames:
            watch = self._watch if self._watch is not None and self._watch[0] == self._awaiting else None
            if watch is not None and not watch[1].agent_sleeps(watch[0], heads_up=self._soon.allowed()):
                region = self._region_reply()  # the reply came just now
                if region is not None:
                    return region
            else:
                # Blocks until a frame comes (the sim wakes a sleeping agent with one), at
                # most LIVENESS_CHECK_S (SO_RCVTIMEO).
                try:
                    self._read(True)
                finally:
                    if watch is not None:
                        watch[1].agent_wakes()
                if watch is not None:
                    region = self._after_heads_up(watch[0])
                    if region is not None:
                        return region
        return self._frames.popleft() if self._frames else None

    def _recv_frame_nowait(self) -> Any:
        region = self._region_reply() or self._take_held()
        if region is not None:
            return region
        if not self._frames:
            self._read(False)
        return self._frames.popleft() if self._frames else None

    # A stream has no stuck state: a late reply arrives later and is dropped by
    # seq, so neither a timeout nor reconnect() need to do anything. close()
    # leaves the pipe open: it belongs to the launcher (SimProcess.pipe).

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


__all__ = ["AGENT_SPIN_S", "PipeConnection"]
