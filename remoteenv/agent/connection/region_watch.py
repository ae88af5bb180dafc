"""The agent's watch of a request posted in a sim's shared region (the fast lane).

Runs in the agent process: the part of :class:`~remoteenv.agent.connection.pipe_connection.PipeConnection`
that posts ``step_batch`` requests in the region of its sim
(:mod:`remoteenv.wire.shared_memory.doorbell`) and looks there for their
replies: within the connection's frame reading (:meth:`RegionWatch._region_reply`,
the heads-up's hot wait) and, for a vector step that waits for nothing else,
on its own (:meth:`RegionWatch.wait_region`: no frame handled, no reply map
made while the reply comes in the region).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory.doorbell import Doorbell
from remoteenv.wire.shared_memory.hot_wait import HotWait

#: A hot wait for a region reply reads the pipe (for an error or another frame) once every this many looks.
PIPE_LOOK_EVERY = 4
#: Longest frame :meth:`RegionWatch._drop_answered` decodes to see whether it answers anything
#: (a wake-up or a heads-up takes a few dozen bytes; anything longer is left to ``receive``).
_SMALL_FRAME = 64


class RegionWatch:
    """The fast lane's side of a pipe connection (a mixin of
    :class:`~remoteenv.agent.connection.pipe_connection.PipeConnection`, which
    sets the attributes below)."""

    instance: int
    closed: bool
    heads_ups: int
    _seq: int
    _unanswered: Any
    _frames: deque[Any]
    _held: dict[int, dict[str, Any]]
    _eof: bool
    _watch: tuple[int, Doorbell] | None
    _watch_plain: bool
    _watch_rang: bool
    _awaiting: int
    _hot: HotWait
    _lane_hot: HotWait
    _soon: HotWait
    _read: Callable[[bool], None]
    _read_quietly: Callable[[bool], bool]
    _send_frame: Callable[[bytes], None]

    def post(self, doorbell: Doorbell, n: int, named: bool, think_s: float = 0.0, plain: bool = False) -> int:
        """Post a ``step_batch`` whose ops, worlds and actions are in the shared
        region (written by the caller; see :mod:`remoteenv.wire.shared_memory.doorbell`);
        its frame goes on the pipe only when the sim sleeps. ``think_s``: the
        agent's think time before it (seconds, 0: not told; the doorbell's
        ``AGENT_THINK_US``); ``plain``: every position steps, none resets
        first (its reply may be waited for hot, see :data:`LANE_SPIN_S`). Returns its ``seq``:
        its reply comes as a frame or in the region (a reply map with
        ``"region": true`` either way)."""
        if self.closed:
            raise RemoteEnvError(
                f"connection to sim instance {self.instance} is closed", kind="state", instance=self.instance
            )
        self._seq += 1
        seq = self._seq
        self._unanswered[seq] = None
        self._watch = (seq, doorbell)
        self._watch_plain = plain
        # A sim that slept (rung) wakes first: this wait does not show how soon the lane answers.
        self._watch_rang = doorbell.post(seq, n, named, think_s)
        if self._watch_rang:
            self._send_frame(protocol.region_ring(seq))
        return seq

    def _region_reply(self) -> dict[str, Any] | None:
        """The awaited reply, if it is the region's and the region holds it
        (then the watch ends). Frames for requests sent later may be buffered
        already: they wait for their turn (replies come in request order)."""
        watch = self._watch
        if watch is None or watch[0] != self._awaiting or not watch[1].answered(watch[0]):
            return None
        self._watch = None
        return protocol.region_reply(watch[0])

    def will_block(self) -> bool:
        """The caller is about to block on :attr:`pollable`: make the sim send a
        frame when it answers the region's request. False if the region holds
        the reply already (then do not block); call :meth:`woke` after the block."""
        watch = self._watch
        return watch is None or watch[1].agent_sleeps(watch[0])

    def woke(self) -> None:
        """After a block that :meth:`will_block` prepared: back to watching the region."""
        if self._watch is not None:
            self._watch[1].agent_wakes()

    def wait_region(self, seq: int) -> bool:
        """Wait for the reply to request ``seq``, posted in the region, as
        :meth:`receive` waits for it, while nothing else needs handling: True
        once the region holds it (the request is answered: read its blocks);
        False as soon as anything else must be read first (a frame came or is
        held, the pipe ended, a blocked wait ran out): then :meth:`receive`
        takes over the wait where it stands, and reports what it finds (a sim
        gone, an error reply) as it always does. Raises only for a pipe whose
        framing the sim broke."""
        watch = self._watch
        if watch is None or watch[0] != seq or self._held or self._eof:
            return False
        bell = watch[1]
        if self._frames and not self._drop_answered(seq, bell):
            return False
        self._awaiting = seq
        if not bell.answered(seq):
            hot = self._lane_hot if self._watch_plain else self._hot
            if hot.worth_it():
                start = time.perf_counter()
                looks = 0
                while not bell.answered(seq):
                    if not hot.spin():
                        if not self._watch_rang:
                            hot.waited(float("inf"))
                        break
                    looks += 1
                    if looks % PIPE_LOOK_EVERY == 0 and (
                        not self._read_quietly(False) or (self._frames and not self._drop_answered(seq, bell))
                    ):
                        return False
                else:
                    hot.waited(time.perf_counter() - start)
            if not bell.answered(seq) and not self._block_for(seq, bell):
                return False
        self._watch = None
        self._unanswered.pop(seq, None)
        return True

    def _block_for(self, seq: int, bell: Doorbell) -> bool:
        """Block on the pipe for the region's reply to ``seq`` (asking for a
        heads-up where waiting hot after it is allowed): whether the region holds it after."""
        if bell.agent_sleeps(seq, heads_up=self._soon.allowed()):
            try:
                read = self._read_quietly(True)
            finally:
                bell.agent_wakes()
            if not read:
                return False
            self._drop_answered(seq, bell)
            if self._after_heads_up(seq) is not None:
                return True
            if self._frames:
                return False
        return bell.answered(seq)

    def _drop_answered(self, seq: int, bell: Doorbell) -> bool:
        """Drop the queued frames that ``receive`` would drop unread while it
        waits for ``seq``: a heads-up for an earlier request, a reply to a
        request answered or abandoned already (its ``seq`` neither ``seq`` nor
        still unanswered), and ``seq``'s own wake-up once the region holds its
        reply. These are the wake-ups a sim sends when it answers in the region
        while the agent has stopped watching: read after the reply was taken
        from the region, they would otherwise turn the next lean wait back to
        ``receive``. True once no frame is left."""
        frames = self._frames
        kept = [frame for frame in frames if not self._answers_nothing(frame, seq, bell)]
        if len(kept) != len(frames):
            frames.clear()
            frames.extend(kept)
        return not frames

    def _answers_nothing(self, frame: Any, seq: int, bell: Doorbell) -> bool:
        """Whether ``frame`` is one that :meth:`_drop_answered` drops (a frame it
        cannot decode, or a long one, is left for ``receive`` to report)."""
        if len(frame) > _SMALL_FRAME:
            return False
        try:
            reply = protocol.unpack(frame, max_values=8, big_ints=True)
        except protocol.ProtocolError:
            return False
        if not isinstance(reply, dict):
            return False
        got = reply.get("seq")
        if type(got) is not int or got == -1:
            return False
        if got == seq:
            return reply == protocol.region_reply(seq) and bell.answered(seq)
        return protocol.is_reply_soon(reply) or got not in self._unanswered

    def _after_heads_up(self, seq: int) -> dict[str, Any] | None:
        """If the frames just read hold the sim's heads-up for ``seq`` (its
        physics is done, its reply due), drop it and wait hot for the reply, at
        most :data:`HEADS_UP_WAIT_S`: the region's reply, else None (a frame
        came, the pipe ended or the wait ran out: the caller goes on as after
        any wake-up)."""
        soon = protocol.reply_soon(seq)
        if soon not in self._frames:
            return None
        self._frames.remove(soon)
        self.heads_ups += 1
        if self._frames or not self._soon.begin():
            return None
        while True:
            region = self._region_reply()
            if region is not None:
                return region
            # Yields the CPU between looks: the sim may share this one.
            if not self._soon.spin():
                return None
            # The pipe's end is reported by the caller's wait (which may restart the sim).
            if not self._read_quietly(False) or self._frames:
                return None


__all__ = ["PIPE_LOOK_EVERY", "RegionWatch"]
