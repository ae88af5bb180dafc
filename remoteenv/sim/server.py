"""RemoteControlledAgent: serves a scene's worlds to one agent over the wire.

Runs in the sim process. It binds a ROUTER socket, answers the commands of
:mod:`remoteenv.protocol` and keeps serving after errors in the scene code.
"""

from __future__ import annotations

import json
import os
import signal
import time
import traceback
from typing import Any, Callable

import zmq

from remoteenv.wire import protocol
from remoteenv.wire import spaces as spaces_codec
from remoteenv.wire.actions import check_action
from remoteenv.wire.errors import InvalidAction
from remoteenv.wire.addresses import ipc_path, is_loopback
from remoteenv.sim.base_env import BaseEnv
from remoteenv.wire.hot_wait import HotWait
from remoteenv.sim.channels import PipeChannel, ZmqChannel
from remoteenv.sim.orphan import ParentWatch, parent_alive, remove_private_files
from remoteenv.sim.stepping import LockStepper, make_stepper

_PARENT_CHECK_S = 0.25
#: Longest busy-wait (seconds) for the agent's next request on the local pipe.
SIM_SPIN_S = 1e-3


class RequestError(Exception):
    """Raised by a command handler; becomes a typed error reply."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


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
        real_time, real_time_factor, action_delay: stepping mode, see
            :mod:`remoteenv.sim.stepping`.
        allow_remote: permit binding a non-loopback interface.
        curve_secret_key: this server's Z85 CURVE secret key; turns on CURVE
            encryption (required beyond loopback).
        curve_client_keys: with CURVE, the Z85 public keys of the clients
            allowed to connect (checked by a ZAP handler); None admits any
            client that knows the server's public key.
        private_dir: the launcher's private dir; if the agent dies, this sim
            removes its ``sim-<instance>.*`` files from it (and the dir, last).
        pipe_fd: inherited end of the launcher's socketpair, served besides
            the socket (see "The local pipe" in :mod:`remoteenv.protocol`);
            its end of file stops the server.
    """

    def __init__(
        self,
        envs: list[BaseEnv],
        address: str,
        *,
        instance: int = 0,
        parent_pid: int | None = None,
        ready_file: str | None = None,
        real_time: bool = False,
        real_time_factor: float = 1.0,
        action_delay: int = 0,
        allow_remote: bool = False,
        curve_secret_key: bytes | None = None,
        curve_client_keys: list[bytes] | None = None,
        private_dir: str | None = None,
        pipe_fd: int | None = None,
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
        self.orphaned = False
        self._authenticator: Any = None
        self.steppers = [
            make_stepper(env, real_time=real_time, real_time_factor=real_time_factor,
                         action_delay=action_delay)
            for env in envs
        ]
        self.real_time = real_time
        self._ctx = zmq.Context.instance()
        self.socket = self._ctx.socket(zmq.ROUTER)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
        if curve_secret_key is not None:
            if curve_client_keys is not None:
                self._authenticator = _start_client_key_check(self._ctx, curve_client_keys)
            self.socket.curve_server = True
            self.socket.curve_secretkey = curve_secret_key
        elif not is_loopback(address):
            raise ValueError(f"binding {address!r} beyond loopback requires CURVE keys")
        self.socket.bind(address)
        self.endpoint: str = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        self.channels: list[ZmqChannel | PipeChannel] = [ZmqChannel(self.socket)]
        if pipe_fd is not None:
            self.channels.append(PipeChannel(pipe_fd))
        self._handlers: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
            "handshake": self._handshake,
            "reset": self._reset,
            "step": self._step,
            "render": self._render,
            "close": self._close,
        }
        if not real_time:
            from remoteenv.sim.batch import BatchCommands

            self._handlers.update(BatchCommands(self).handlers())
        self._running = True
        if ready_file:
            tmp = f"{ready_file}.tmp"
            with open(tmp, "w") as f:
                json.dump({"endpoint": self.endpoint, "pid": os.getpid(), "instance": instance}, f)
            os.replace(tmp, ready_file)

    # ------------------------------------------------------------ serving

    def serve(self) -> None:
        """Answer requests until a ``close`` command, SIGTERM/SIGINT or parent death."""

        def _stop(signum: int, _frame: Any) -> None:
            raise SystemExit(128 + signum)

        signal.signal(signal.SIGTERM, _stop)
        watch = None
        if self.parent_pid is not None:
            watch = ParentWatch(self.parent_pid, self.private_dir, self.instance)
            watch.start()
        try:
            if self.real_time:
                from remoteenv.sim.real_time import serve_real_time

                serve_real_time(self)
            else:
                self._serve_lockstep()
        finally:
            self.shutdown()
            gone = self.orphaned or (self.parent_pid is not None and not parent_alive(self.parent_pid))
            if self.private_dir and gone:
                remove_private_files(self.private_dir, self.instance)
            if watch is not None:
                watch.finished()

    def _serve_lockstep(self) -> None:
        poller = zmq.Poller()
        by_pollable = {}
        for channel in self.channels:
            poller.register(channel.pollable, zmq.POLLIN)
            by_pollable[channel.pollable] = channel
        pipe = next((c for c in self.channels if isinstance(c, PipeChannel)), None)
        hot = HotWait(SIM_SPIN_S if pipe is not None else 0.0)
        last_check = time.monotonic()
        while self._running:
            if pipe is not None and hot.worth_it():
                # The agent has been sending its next request quickly: wait hot.
                frames = pipe.receive_spinning(hot.window_s)
                if frames:
                    hot.waited(time.perf_counter() - hot.since)
                    self._answer(pipe, frames)
                    hot.since = time.perf_counter()
                    continue
            events = poller.poll(_PARENT_CHECK_S * 1000)
            for pollable, _ in events:
                channel = by_pollable[pollable]
                frames = channel.receive_nowait()
                if channel is pipe and frames:
                    hot.waited(time.perf_counter() - hot.since)
                self._answer(channel, frames)
                if channel is pipe:
                    hot.since = time.perf_counter()
                if channel.closed:
                    self.pipe_closed()
            now = time.monotonic()
            if not events or now - last_check > _PARENT_CHECK_S:
                self.check_parent()
                last_check = now

    def _answer(self, channel: ZmqChannel | PipeChannel, frames: list[tuple[Any, bytes]]) -> None:
        for reply_to, frame in frames:
            channel.send(reply_to, self.pack_reply(self.handle_frame(frame)))

    def pipe_closed(self) -> None:
        """The local pipe ended: the agent died or closed it. Stop, and leave no files."""
        self.orphaned = True
        self._running = False

    def check_parent(self) -> None:
        """Stop serving if the agent that launched us is gone."""
        if self.parent_pid is not None and not parent_alive(self.parent_pid):
            self.orphaned = True
            self._running = False

    def pack_reply(self, reply: dict[str, Any]) -> bytes:
        """Encode a reply; one that cannot go on the wire becomes a typed error (never raises)."""
        try:
            return protocol.pack(reply)
        except Exception as exc:
            seq = reply.get("seq", -1)
            return protocol.pack(protocol.error_reply(
                seq if isinstance(seq, int) else -1, "scene",
                f"the reply to this request cannot be sent on the wire ({type(exc).__name__}: {exc}); "
                "scene code must return numpy arrays, numbers, strings, lists and str-keyed maps",
                traceback.format_exc(),
            ))

    def handle_frame(self, frame: bytes) -> dict[str, Any]:
        """Decode one request frame and compute its reply (never raises)."""
        try:
            msg = protocol.decode_request(frame)
        except protocol.ProtocolError as exc:
            return protocol.error_reply(-1, "protocol", str(exc))
        return self.handle(msg)

    def handle(self, msg: dict[str, Any]) -> dict[str, Any]:
        """Compute the reply to a decoded request (never raises)."""
        seq = msg["seq"]
        handler = self._handlers.get(msg["cmd"])
        if handler is None:
            return protocol.error_reply(
                seq, "protocol", f"unknown command {msg['cmd']!r}; known: {sorted(self._handlers)}"
            )
        try:
            reply = handler(msg)
        except RequestError as exc:
            return protocol.error_reply(seq, exc.kind, str(exc))
        except Exception as exc:
            return protocol.error_reply(
                seq, "scene", f"{type(exc).__name__}: {exc}", traceback.format_exc()
            )
        reply["seq"] = seq
        reply["ok"] = True
        return reply

    def shutdown(self) -> None:
        """Close the envs and the socket (libzmq unlinks an ipc socket file it bound)."""
        for env in self.envs:
            try:
                env.close()
            except Exception:
                traceback.print_exc()
        self.socket.close(linger=0)
        for channel in self.channels:
            if isinstance(channel, PipeChannel):
                channel.close()
        if self._authenticator is not None:
            self._authenticator.stop()
        path = ipc_path(self.endpoint)
        if path is not None:
            try:
                os.unlink(path)
            except OSError:
                pass

    # ------------------------------------------------------------ commands

    def _world(self, msg: dict[str, Any]) -> int:
        world = msg.get("world", 0)
        if not isinstance(world, int) or isinstance(world, bool) or not 0 <= world < len(self.envs):
            raise RequestError(
                "protocol", f"world {world!r} out of range; this process hosts {len(self.envs)}"
            )
        return world

    def _handshake(self, msg: dict[str, Any]) -> dict[str, Any]:
        version = msg.get("protocol")
        if version != protocol.PROTOCOL_VERSION:
            raise RequestError(
                "protocol",
                f"protocol version mismatch: agent speaks {version!r}, sim instance "
                f"{self.instance} speaks {protocol.PROTOCOL_VERSION}",
            )
        env = self.envs[0]
        return {
            "protocol": protocol.PROTOCOL_VERSION,
            "env_id": env.env_id,
            "instance": self.instance,
            "pid": os.getpid(),
            "num_worlds": len(self.envs),
            "observation_space": spaces_codec.space_to_wire(env.observation_space),
            "action_space": spaces_codec.space_to_wire(env.action_space),
            "metadata": {
                "render_modes": list(env.metadata.get("render_modes", [])),
                "render_fps": int(round(1.0 / env.dt)),
                "dt": float(env.dt),
                "timestep": float(env.model.opt.timestep),
                "frame_skip": env.frame_skip,
            },
            "stepping": self.steppers[0].describe(),
        }

    def _reset(self, msg: dict[str, Any]) -> dict[str, Any]:
        world = self._world(msg)
        seed = msg.get("seed")
        if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool) or seed < 0):
            raise RequestError("protocol", f"seed must be a non-negative int or nil, got {seed!r}")
        options = msg.get("options")
        if options is not None and not isinstance(options, dict):
            raise RequestError("protocol", f"options must be a map or nil, got {type(options).__name__}")
        obs, info = self.steppers[world].reset(seed=seed, options=options)
        return {"obs": obs, "info": info}

    def _step(self, msg: dict[str, Any]) -> dict[str, Any]:
        world = self._world(msg)
        stepper = self.steppers[world]
        if not stepper.has_reset:
            raise RequestError("state", f"step before reset on world {world} of instance {self.instance}")
        action = validate_action(self.envs[world], msg.get("action"))
        return stepper.step(action)

    def _render(self, msg: dict[str, Any]) -> dict[str, Any]:
        world = self._world(msg)
        return {"frame": self.envs[world].render()}

    def _close(self, msg: dict[str, Any]) -> dict[str, Any]:
        self._running = False
        return {}


def _start_client_key_check(ctx: zmq.Context, client_keys: list[bytes]) -> Any:
    """Run a ZAP handler thread that admits only CURVE clients whose public key is listed."""
    from zmq.auth.thread import ThreadAuthenticator

    allowed = frozenset(bytes(k).strip() for k in client_keys)

    class _Allowed:
        def callback(self, domain: str, key: bytes) -> bool:
            return bytes(key) in allowed

    auth = ThreadAuthenticator(ctx)
    auth.start()
    auth.configure_curve_callback("*", credentials_provider=_Allowed())
    return auth


def validate_action(env: BaseEnv, action: Any) -> Any:
    """``action`` checked against the env's action space (:mod:`remoteenv.wire.actions`)."""
    try:
        return check_action(env.action_space, action)
    except InvalidAction as exc:
        raise RequestError("invalid_action", str(exc)) from None


__all__ = ["RemoteControlledAgent", "RequestError", "validate_action", "LockStepper"]
