"""How the sim server's loop waits for work, one pass at a time.

Runs in the sim process (:meth:`remoteenv.sim.serving.sim_server.RemoteControlledAgent.serve`).
With no deadline (lock-step) a pass waits for requests: hot on the local pipe
while the agent has been answering quickly (:class:`~remoteenv.wire.shared_memory.hot_wait.HotWait`)
and, when it posts in the pipe's shared region, said it thinks briefly
between its vector steps (the doorbell's ``AGENT_THINK_US``), else blocking
on every channel for up to :data:`~remoteenv.sim.process.orphan.CHECK_INTERVAL_S`.
With a deadline (real time) a pass sleeps with ``select`` until ``spin_s``
before it, spins the rest, runs the work due and reads every channel. What
arrives goes to the server's ``answer``, except a request posted in the
pipe's region that came alone, which goes to its ``plain`` first (a plain
step of every world, served without the dispatch:
:class:`~remoteenv.sim.stepping.plain_region_step.PlainRegionStep`); an
ended pipe to its ``pipe_closed``.
"""

from __future__ import annotations

import select
import time
from collections.abc import Callable
from typing import Any

import zmq

from remoteenv.sim.process.orphan import CHECK_INTERVAL_S
from remoteenv.sim.stepping.interfaces import Stepping
from remoteenv.sim.transport.channels import Channel, Outgoing, PipeChannel, ZmqChannel
from remoteenv.wire.shared_memory.hot_wait import HotWait

_CHECK_INTERVAL_MS = round(CHECK_INTERVAL_S * 1000)


class ServingWaits:
    """The waits of one ``serve`` call over ``router`` and the launcher's ``pipe``.

    Args:
        router, pipe: the server's channels (the launching agent's pipe is read first).
        hot_window_s: longest busy-wait (seconds) for the agent's next request on the pipe (0: never).
        hot_patience: waits in a row that outlast ``hot_window_s`` before the
            next ones start cold (see :class:`~remoteenv.wire.shared_memory.hot_wait.HotWait`).
        think_limit_s: no busy-wait after a region request whose agent thought
            longer than this (seconds) before it: the agent's own code (a
            policy, an update) then runs on the CPUs a spinning sim would take.
        spin_s: wall seconds before a deadline at which waiting turns from sleeping to spinning.
        answer: answers the frames a channel gave.
        plain: serves a request found posted in the pipe's region, given its
            ``seq`` and the pipe, when it is a plain step of every world; False
            if it took nothing (then ``answer`` gets it). None: ``answer`` gets all.
        send: sends a reply the stepping completed.
        pipe_closed: called when the pipe has ended.
    """

    def __init__(
        self,
        router: ZmqChannel,
        pipe: PipeChannel | None,
        *,
        hot_window_s: float,
        hot_patience: int = 1,
        think_limit_s: float = float("inf"),
        spin_s: float,
        answer: Callable[[Channel, list[tuple[Any, Any]]], None],
        send: Callable[[Outgoing], None],
        pipe_closed: Callable[[], None],
        plain: Callable[[int, PipeChannel], bool] | None = None,
    ) -> None:
        self.router, self.pipe = router, pipe
        self.hot = HotWait(hot_window_s, hot_patience)
        self.served: list[Channel] = [router] if pipe is None else [pipe, router]  # the launching agent first
        self.poller = zmq.Poller()
        for channel in self.served:
            self.poller.register(channel.pollable, zmq.POLLIN)
        self.fds = [channel.fd for channel in self.served]
        self.spin_s = spin_s
        self.think_limit_s = think_limit_s
        self._answer, self._send, self._pipe_closed = answer, send, pipe_closed
        self._plain = plain

    def for_requests(self) -> bool | None:
        """One lock-step pass: wait for requests and answer them. Returns whether
        nothing came (idle), or None when a request was answered from the pipe
        at once (the loop goes round again before anything else)."""
        pipe, router, hot = self.pipe, self.router, self.hot
        # A wait through a think the agent announced (its update, a long think time)
        # says nothing of how soon its requests follow its steps: it is not recorded,
        # so the first request after it is waited for hot again.
        thinks = pipe is not None and self._agent_thinks(pipe)
        if pipe is not None and not thinks and hot.worth_it():
            # The agent has been sending its next request quickly: wait hot.
            frames = pipe.receive_spinning(hot)
            if frames:
                hot.waited(time.perf_counter() - hot.since)
                self._answer_pipe(pipe, frames)
                hot.since = time.perf_counter()
                return None
            if pipe.closed:
                self._pipe_closed()
                return None
        if pipe is not None and not router.more:
            # About to block: a request posted in the pipe's region comes with a frame from now on.
            frames = pipe.settle()
            if frames:
                self._answer_pipe(pipe, frames)
                return None
        # Frames left waiting in the router's backlog: look, do not wait.
        events = dict(self.poller.poll(0 if router.more else _CHECK_INTERVAL_MS))
        for channel in self.served:
            if channel.pollable not in events and not channel.more:
                continue
            frames = channel.receive_nowait()
            if channel is pipe:
                if frames and not thinks:
                    hot.waited(time.perf_counter() - hot.since)
                self._answer_pipe(pipe, frames)
                hot.since = time.perf_counter()
            else:
                self._answer(channel, frames)
            if channel.closed:
                self._pipe_closed()
        return not events

    def _answer_pipe(self, pipe: PipeChannel, frames: list[tuple[Any, Any]]) -> None:
        """Answer what the pipe gave: a request posted in its region alone goes
        to ``plain`` first (see the constructor), anything else to ``answer``."""
        plain = self._plain
        if plain is not None and len(frames) == 1:
            frame = frames[0][1]
            if type(frame) is dict and plain(frame["seq"], pipe):  # a region request (protocol.region_request)
                return
        self._answer(pipe, frames)

    def _agent_thinks(self, pipe: PipeChannel) -> bool:
        """Whether the agent said it thinks longer than :attr:`think_limit_s` between
        steps, or that its caller has begun a long think now (``AGENT_AWAY``)."""
        lane = pipe.lane
        return lane is not None and (lane.agent_think_s > self.think_limit_s or lane.agent_away())

    def until(self, deadline: float, now: float, stepping: Stepping, channels: list[Channel]) -> None:
        """One real-time pass: run what is due at ``now`` (sending the replies it
        completes), or sleep towards ``deadline`` unless one of ``channels`` holds
        frames already; then read every channel."""
        if deadline <= now:
            for outgoing in stepping.run_due(now):
                self._send(outgoing)
        else:
            timeout = min(deadline - now, CHECK_INTERVAL_S)
            if timeout > self.spin_s and not any(channel.more for channel in channels):
                # Wake a little early: the kernel's wake-up latency is then
                # absorbed by spinning (looping) instead of making us late.
                select.select(self.fds, [], [], timeout - self.spin_s)
        # The ZeroMQ descriptor is edge-triggered: read every channel.
        for channel in self.served:
            self._answer(channel, channel.receive_nowait())
            if channel.closed:
                self._pipe_closed()


__all__ = ["ServingWaits"]
