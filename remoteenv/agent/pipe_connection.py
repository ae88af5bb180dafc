"""The agent's end of the local pipe to a sim this process launched (the sim's
end is its :class:`~remoteenv.sim.channels.PipeChannel`).

Runs in the agent process. A Unix socketpair carrying length-prefixed frames
(see :mod:`remoteenv.wire.protocol`): no I/O threads sit between the two
processes, and the sim's death shows at once as end of file. Waits for a
reply start hot while replies have been quick (:mod:`remoteenv.wire.hot_wait`).
"""

from __future__ import annotations

import socket
import struct
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.sim_connection import LIVENESS_CHECK_S, SimConnection
from remoteenv.wire import protocol
from remoteenv.wire.hot_wait import HotWait

#: How long (seconds) to wait for a sim that closed its pipe to be reaped, so
#: that its exit code or signal can be reported.
_EXIT_REPORT_S = 2.0
#: Longest busy-wait (seconds) for a reply on the local pipe (see :mod:`remoteenv.wire.hot_wait`).
AGENT_SPIN_S = 200e-6


class PipeConnection(SimConnection):
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
        self._eof = False
        self._hot = HotWait(AGENT_SPIN_S)
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
        if self._eof:
            self._check_alive("a reply", closed=True)
        data = self._decoder.recv_from(self.pipe, wait)
        if data is None:
            return
        if not data:
            self._eof = True
            self._check_alive("a reply", closed=True)
        try:
            self._frames.extend(self._decoder.feed(data))
        except protocol.ProtocolError as exc:
            raise RemoteEnvError(
                f"sim instance {self.instance} broke the pipe framing: {exc}", kind="protocol", instance=self.instance
            ) from None

    def _recv_frame(self) -> bytes | None:
        if not self._frames and self._hot.worth_it():
            start = time.perf_counter()
            self._read(False)
            while not self._frames and self._hot.spin():
                self._read(False)
            if self._frames:
                self._hot.waited(time.perf_counter() - start)
                return self._frames.popleft()
            self._hot.waited(float("inf"))
        if not self._frames:
            self._read(True)
        return self._frames.popleft() if self._frames else None

    def _recv_frame_nowait(self) -> bytes | None:
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
