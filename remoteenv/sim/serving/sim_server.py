"""RemoteControlledAgent: serves a scene's worlds to one agent over the wire.

Runs in the sim process. It binds a ROUTER socket (and serves the launcher's
local pipe beside it), answers the commands of :mod:`remoteenv.wire.protocol`
from one command table and keeps serving after errors in the scene code.

One loop serves both stepping modes (its waits: :mod:`~remoteenv.sim.serving.waits`;
its command table: :mod:`~remoteenv.sim.serving.command_table`). It asks the server's
:class:`~remoteenv.sim.stepping.interfaces.Stepping` for its next deadline: with none
(always, in lock-step) it blocks on its channels until a request arrives,
busy-waiting for a short while first when the agent on the local pipe has
been quick (:data:`SIM_SPIN_S`); with one (real time) it sleeps until just
before it with ``select`` (microsecond timeouts), spins the rest, runs the
work due and sends the replies that completes, and reads requests between
substeps.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import zmq

from remoteenv.sim.process.lifecycle import exit_on_sigterm, remove_ipc_file, write_ready_file
from remoteenv.sim.process.orphan import CHECK_INTERVAL_S, AgentWatch, parent_alive
from remoteenv.sim.process.pin_release import PinRelease
from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.serving.command_table import build_table, pack_reply
from remoteenv.sim.serving.waits import ServingWaits
from remoteenv.sim.stepping.real_time import Clock
from remoteenv.sim.transport.channels import Channel, Outgoing, PipeChannel, ZmqChannel
from remoteenv.sim.transport.limits import EXPENSIVE_COMMANDS, EXPENSIVE_PER_PASS, raise_fd_limit, return_large_frees
from remoteenv.sim.transport.router import open_router
from remoteenv.sim.transport.router_close import close_router
from remoteenv.wire import protocol
from remoteenv.wire.addresses import is_loopback
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.wire_errors import PROTOCOL

log = logging.getLogger(__name__)

#: Longest busy-wait (seconds) for the agent's next request on the local pipe.
SIM_SPIN_S = 1e-3
#: Waits for the agent's next request in a row that outlast :data:`SIM_SPIN_S`
#: before the next ones start cold: an agent late now and then (its caller
#: preempted, a slow host's hiccup) is still waited for hot, as a sim asleep
#: costs the request a wake-up and its physics a slower start (docs/performance-history.md,
#: "The sim's patience with a late request").
SIM_SPIN_PATIENCE = 3
#: Longest think time (seconds) of an agent whose next request is waited for
#: hot: beyond it the agent runs its own code (a policy, an update) on the
#: CPUs a spinning sim would take from it (see :class:`~remoteenv.sim.serving.waits.ServingWaits`).
AGENT_THINK_SPIN_S = 200e-6
#: Wall seconds before a deadline at which waiting turns from sleeping to spinning.
DEADLINE_SPIN_S = 0.0003


class RemoteControlledAgent:
    """Serves ``envs`` (one or more worlds of one scene) at ``address``.

    Args:
        envs: the worlds this process hosts; requests address them by index.
        address: ZeroMQ endpoint to bind, e.g. ``ipc:///tmp/x/sim-0.sock`` or
            ``tcp://127.0.0.1:*`` (the OS picks the port; see ``endpoint``).
        instance: the index of this sim process among those an agent launched.
        parent_pid: exit when this process is no longer our parent (the agent
            died). None disables the check.
        ready_file: once bound, write ``{"endpoint", "pid", "instance"}`` as JSON
            here (atomically), so the launcher knows where and that we listen.
        run: how the worlds run (:class:`~remoteenv.wire.run_options.options.RunOptions`):
            lock-step (:mod:`remoteenv.sim.stepping.lock_step`, with its delays
            and channel rules) or real time (:mod:`remoteenv.sim.stepping.real_time`:
            physics paced to the wall clock, its factor, regime and emulated link).
        seed: launch seed of world 0 (world ``w``: ``seed + w``), seeding the
            delay streams until a reset brings a seed.
        allow_remote: permit binding a non-loopback interface.
        curve_secret_key: this server's Z85 CURVE secret key; turns on CURVE
            encryption (required beyond loopback).
        curve_client_keys: with CURVE, the Z85 public keys of the clients
            allowed to connect (checked by a ZAP handler); None admits any
            client that knows the server's public key.
        private_dir: the launcher's private dir; if the agent dies, this sim
            removes its ``sim-<instance>.*`` files from it (and the dir, last).
        pipe_fd: inherited end of the launcher's socketpair, served besides
            the socket (see "The local pipe" in :mod:`remoteenv.wire.protocol`);
            its end of file stops the server.
        clock: the loop's and real-time stepping's clock (seconds, monotonic).
        world_factory: makes a scratch world like ``envs[0]`` (never served), for
            measuring what a world's whole tick costs when a handshake asks
            (:mod:`remoteenv.sim.scene.world_cost`); None: that cost is estimated.
    """

    def __init__(
        self,
        envs: list[BaseEnv],
        address: str,
        *,
        instance: int = 0,
        parent_pid: int | None = None,
        ready_file: str | None = None,
        run: RunOptions = RunOptions(),
        seed: int | None = None,
        allow_remote: bool = False,
        curve_secret_key: bytes | None = None,
        curve_client_keys: list[bytes] | None = None,
        private_dir: str | None = None,
        pipe_fd: int | None = None,
        clock: Clock = time.monotonic,
        world_factory: Callable[[], BaseEnv] | None = None,
    ) -> None:
        if not envs:
            raise ValueError("RemoteControlledAgent needs at least one env")
        if not is_loopback(address) and not allow_remote:
            raise ValueError(
                f"refusing to bind {address!r}: not ipc:// or loopback. Binding another "
                "interface needs allow_remote=True and CURVE keys."
            )
        self.envs = envs
        self.instance = instance
        self.parent_pid = parent_pid
        self.private_dir = private_dir
        self.run = run
        self.real_time = run.real_time
        self.clock = clock
        self.orphaned = False
        self._pipe_ended = False
        self._pipe = PipeChannel(pipe_fd) if pipe_fd is not None else None
        self.stepping, self._table, drivers = build_table(
            envs,
            instance,
            self.stop,
            self._pipe,
            run,
            seed=seed,
            clock=clock,
            world_factory=world_factory,
        )
        #: Who drives each world (:mod:`remoteenv.sim.transport.drivers`).
        self.drivers = drivers
        raise_fd_limit()
        return_large_frees()
        # A context of its own: its ZAP handler is this server's gate.
        self._ctx: zmq.Context[Any] = zmq.Context()
        try:
            self.socket, self._gate = open_router(self._ctx, address, curve_secret_key, curve_client_keys)
        except BaseException:
            self._ctx.term()
            raise
        self.endpoint: str = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        #: The ROUTER's channel: the drivers' frames first, the others' within budgets.
        self.router = ZmqChannel(
            self.socket,
            owners=lambda: drivers.routing_ids,
            disconnected=self._gate.take_disconnected,
            gone=lambda routing_id: drivers.release((self.router, routing_id)),
        )
        self.channels: list[Channel] = [self.router]
        if self._pipe is not None:
            self.channels.append(self._pipe)
        self._expensive_left = EXPENSIVE_PER_PASS
        self._running = True
        #: Wall seconds before a deadline at which waiting turns from sleeping to spinning.
        self.deadline_spin_s = DEADLINE_SPIN_S
        if ready_file:
            write_ready_file(ready_file, self.endpoint, instance)

    @property
    def running(self) -> bool:
        """True until a ``close`` command, the pipe's end or the parent's death stops serving."""
        return self._running

    @property
    def commands(self) -> list[str]:
        """The commands this server answers, sorted."""
        return self._table.commands

    def stop(self) -> None:
        """Stop serving once the request in hand is answered."""
        self._running = False

    # ------------------------------------------------------------ serving

    def serve(self) -> None:
        """Answer requests until a ``close`` command, SIGTERM/SIGINT or parent death."""
        exit_on_sigterm()
        watch = AgentWatch(self.parent_pid, self.private_dir, self.instance)
        try:
            self._serve_until_stopped()
        finally:
            self.shutdown()
            watch.finish(orphaned=self.orphaned, pipe_ended=self._pipe_ended)

    def _serve_until_stopped(self) -> None:
        stepping, clock, pipe = self.stepping, self.clock, self._pipe
        # A sim the agent pinned takes its CPUs back from a busy neighbour (lock step only).
        pin = None if self.real_time else PinRelease(self.instance)
        # Busy-waiting for the agent's next request pays in lock-step; in real
        # time the loop's own waits are paced by the deadlines instead.
        waits = ServingWaits(
            self.router,
            pipe,
            hot_window_s=SIM_SPIN_S if pipe is not None and not self.real_time else 0.0,
            hot_patience=SIM_SPIN_PATIENCE,
            think_limit_s=AGENT_THINK_SPIN_S,
            spin_s=self.deadline_spin_s,
            answer=self._answer if pin is None else pin.watching(self._answer),
            send=self._send_later,
            pipe_closed=self.pipe_closed,
            plain=None if pin is None or self._table.plain is None else self._plain_answer(pin),
        )
        last_check = clock()
        while self._running:
            self._expensive_left = EXPENSIVE_PER_PASS
            deadline = stepping.next_deadline()
            if deadline is None:
                idle = waits.for_requests()
                if idle is None:  # answered at once from the pipe
                    continue
            else:
                waits.until(deadline, clock(), stepping, self.channels)
                idle = False
            now = clock()
            if idle or now - last_check > CHECK_INTERVAL_S:
                self.check_parent()
                last_check = now

    def _plain_answer(self, pin: PinRelease) -> Callable[[int, PipeChannel], bool]:
        """What serves a plain step of every world posted in the pipe's region
        (:meth:`~remoteenv.sim.serving.command_table.CommandTable.handle_plain_region`),
        watched by ``pin`` as :meth:`_answer` is; False when it took nothing."""
        table = self._table

        def plain(seq: int, pipe: PipeChannel) -> bool:
            taken, reply = table.handle_plain_region(seq, pipe)
            if not taken:
                return False
            if reply is not None:
                self._reply(pipe, None, reply)
            pin.answered()
            return True

        return plain

    def _answer(self, channel: Channel, frames: list[tuple[Any, Any]]) -> None:
        router = self.router
        for i, (reply_to, frame) in enumerate(frames):
            reply: dict[str, Any] | None
            if type(frame) is dict:  # a request found in the pipe's region, decoded (protocol.region_request)
                reply = self._table.handle_region(frame, channel)
            else:
                try:
                    msg = protocol.decode_request(frame)
                except protocol.ProtocolError as exc:
                    reply = protocol.error_reply(-1, PROTOCOL, str(exc))
                else:
                    if msg["cmd"] in EXPENSIVE_COMMANDS and channel is router and router.budgeted(reply_to):
                        if self._expensive_left <= 0:  # this pass's share is spent: the rest waits
                            router.defer(frames[i:])
                            return
                        self._expensive_left -= 1
                    reply = self.handle(msg, channel, reply_to)
            if reply is not None:
                self._reply(channel, reply_to, reply)

    def _reply(self, channel: Channel, reply_to: Any, reply: dict[str, Any]) -> None:
        """Send ``reply`` to ``reply_to`` on ``channel``."""
        payload = pack_reply(reply)
        if self.stepping.clock_waiting:  # a reset was answered: its world's clock starts as the reply goes
            # Read before sending: the reset's reply never reaches the
            # agent before substep 0's deadline, so no action can.
            self.stepping.start_clocks(self.clock())
        channel.send(reply_to, payload)

    def _send_later(self, outgoing: Outgoing) -> None:
        channel, reply_to, reply = outgoing
        if channel is not None:
            channel.send(reply_to, pack_reply(reply))

    def pipe_closed(self) -> None:
        """The local pipe ended: the agent died or closed it. Stop; if the agent is
        gone (or nobody can tell: no parent pid), leave no files."""
        self._pipe_ended = True
        if self.parent_pid is None:
            self.orphaned = True
        self._running = False

    def check_parent(self) -> None:
        """Stop serving if the agent that launched us is gone."""
        if self.parent_pid is not None and not parent_alive(self.parent_pid):
            self.orphaned = True
            self._running = False

    # ------------------------------------------------------------ requests

    def pack_reply(self, reply: dict[str, Any]) -> bytes:
        """Encode a reply; one that cannot go on the wire becomes a typed error (never raises)."""
        return pack_reply(reply)

    def handle_frame(self, frame: bytes, channel: Channel | None = None, reply_to: Any = None) -> dict[str, Any] | None:
        """Decode one request frame and compute its reply (never raises); see :meth:`handle`.

        A frame that is not a request gets a ``protocol`` error with ``seq`` -1.
        """
        try:
            msg = protocol.decode_request(frame)
        except protocol.ProtocolError as exc:
            return protocol.error_reply(-1, PROTOCOL, str(exc))
        return self.handle(msg, channel, reply_to)

    def handle(
        self, msg: dict[str, Any], channel: Channel | None = None, reply_to: Any = None
    ) -> dict[str, Any] | None:
        """The reply to a decoded request (never raises), or None if it comes later.

        Only a real-time ``step`` answers later: its reply goes to ``reply_to``
        on ``channel`` when its tick ends (nowhere if ``channel`` is None).
        """
        return self._table.handle(msg, channel, reply_to)

    def shutdown(self) -> None:
        """Close the envs, then the socket, its gate and its context (waiting for
        those at most :data:`~remoteenv.sim.transport.router_close.CLOSE_WAIT_S`),
        the pipe, and remove an ipc socket file that is left."""
        for env in self.envs:
            try:
                env.close()
            except Exception:
                log.exception("closing %s (a world of sim instance %d) raised", type(env).__name__, self.instance)
        close_router(self._gate, self.socket, self._ctx, self.instance)
        if self._pipe is not None:
            self._pipe.close()
        remove_ipc_file(self.endpoint)


__all__ = ["AGENT_THINK_SPIN_S", "DEADLINE_SPIN_S", "SIM_SPIN_S", "RemoteControlledAgent"]
