"""A remoteenv-protocol server written from the spec alone: Gymnasium's
in-process ``CartPole-v1`` behind pyzmq + msgpack.

It stands in for a real robot bridge: it imports nothing from remoteenv (not
the sim side, not the wire layer); the array extension type, the space maps
and the error replies are implemented here from the spec in
``remoteenv/wire/protocol.py``. It binds 127.0.0.1 on an OS-chosen port (or
an ipc socket in a private temp dir), writes a launch-info file
(``"remoteenv-launch/1"``) that ``OpenAIRemoteEnv.attach`` and ``python -m
remoteenv check`` read, and serves until ``close``, SIGTERM or its parent's
death. It is lock-step and offers no batch commands; its handshake says so
with a ``commands`` list.

Usage: ``python gym_cartpole_server.py --out launch.json [--worlds K]
[--transport tcp|ipc] [--flaw NAME]``. ``--flaw`` breaks one rule on
purpose, so tests can see the compliance checks catch it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import reprlib
import shutil
import signal
import socket
import struct
import tempfile
import traceback
from typing import Any

import gymnasium as gym
import msgpack
import numpy as np
import zmq

PROTOCOL_VERSION = 1
MAX_MESSAGE_BYTES = 32 * 1024 * 1024
EXT_ARRAY = 1
MAX_NDIM = 32
WIRE_DTYPES = {"|b1", "|i1", "<i2", "<i4", "<i8", "|u1", "<u2", "<u4", "<u8", "<f2", "<f4", "<f8"}
COMMANDS = ["handshake", "reset", "step", "render", "close"]
FLAWS = ("seq", "obs-dtype", "silent-garbage")

_short = reprlib.Repr()
_short.maxstring = _short.maxother = 80


class RequestError(Exception):
    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


# ---------------------------------------------------------------- values on the wire


def _to_wire(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        dt = obj.dtype.newbyteorder("<") if obj.dtype.itemsize > 1 else obj.dtype
        arr = np.ascontiguousarray(obj, dtype=dt)
        name = dt.str.encode("ascii")
        head = bytes([len(name)]) + name + bytes([arr.ndim]) + struct.pack(f"<{arr.ndim}Q", *arr.shape)
        return msgpack.ExtType(EXT_ARRAY, head + arr.tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot send a {type(obj).__name__}")


def _from_wire(code: int, data: bytes) -> Any:
    if code != EXT_ARRAY:
        raise ValueError(f"unknown extension type {code}")
    n = data[0]
    dtype = data[1 : 1 + n].decode("ascii")
    ndim = data[1 + n]
    if dtype not in WIRE_DTYPES or ndim > MAX_NDIM:
        raise ValueError(f"array dtype {dtype!r} or ndim {ndim} is not allowed")
    shape = struct.unpack_from(f"<{ndim}Q", data, 2 + n)
    offset = 2 + n + 8 * ndim
    count = math.prod(shape)
    if count * np.dtype(dtype).itemsize != len(data) - offset:
        raise ValueError(f"array data of {len(data) - offset} bytes does not fit shape {list(shape)}")
    return np.frombuffer(data, dtype, count, offset).reshape(shape).copy()


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_to_wire, use_bin_type=True)


def error(seq: int, kind: str, message: str, tb: str = "") -> dict[str, Any]:
    return {"seq": seq, "ok": False, "error": {"kind": kind, "message": message, "traceback": tb}}


# ---------------------------------------------------------------- the bridge


class CartPoleBridge:
    """``worlds`` copies of CartPole-v1 served over the protocol's commands."""

    def __init__(self, worlds: int, flaw: str | None = None) -> None:
        self.envs = [gym.make("CartPole-v1") for _ in range(worlds)]
        self.started = [False] * worlds
        self.flaw = flaw
        self.running = True

    def answer(self, frame: bytes) -> dict[str, Any] | None:
        """The reply to one frame (None: no reply, only under the ``silent-garbage`` flaw)."""
        try:
            msg = msgpack.unpackb(frame, raw=False, ext_hook=_from_wire, strict_map_key=True)
            seq, cmd = msg["seq"], msg["cmd"]
            if type(seq) is not int or type(cmd) is not str:
                raise TypeError("a request needs an int seq and a str cmd")
        except Exception as exc:
            if self.flaw == "silent-garbage":
                return None
            return error(-1, "protocol", f"not a request: {type(exc).__name__}: {_short.repr(str(exc))}")
        handler = getattr(self, f"cmd_{cmd}", None) if cmd in COMMANDS else None
        if handler is None:
            return error(seq, "protocol", f"unknown command {_short.repr(cmd)}; known: {COMMANDS}")
        try:
            reply = handler(msg)
        except RequestError as exc:
            return error(seq, exc.kind, str(exc))
        except Exception as exc:
            return error(seq, "scene", f"{type(exc).__name__}: {exc}", traceback.format_exc())
        if self.flaw == "seq" and cmd == "step":
            seq += 1
        return {"seq": seq, "ok": True, **reply}

    def _world(self, msg: dict[str, Any]) -> int:
        world = msg.get("world", 0)
        if type(world) is not int or not 0 <= world < len(self.envs):
            raise RequestError(
                "protocol", f"world {_short.repr(world)} out of range; this server hosts {len(self.envs)}"
            )
        return world

    def _obs(self, obs: np.ndarray) -> np.ndarray:
        return obs.astype(np.float64) if self.flaw == "obs-dtype" else obs

    def cmd_handshake(self, msg: dict[str, Any]) -> dict[str, Any]:
        if msg.get("protocol") != PROTOCOL_VERSION:
            raise RequestError(
                "protocol",
                f"protocol version mismatch: the agent speaks "
                f"{_short.repr(msg.get('protocol'))}, this server speaks {PROTOCOL_VERSION}",
            )
        env = self.envs[0]
        obs_space, act_space = env.observation_space, env.action_space
        tau = float(env.unwrapped.tau)
        return {
            "protocol": PROTOCOL_VERSION,
            "env_id": "CartPole-v1",
            "instance": 0,
            "pid": os.getpid(),
            "num_worlds": len(self.envs),
            "observation_space": {
                "type": "Box",
                "low": obs_space.low,
                "high": obs_space.high,
                "dtype": obs_space.dtype.str,
            },
            "action_space": {"type": "Discrete", "n": int(act_space.n), "start": int(act_space.start)},
            "metadata": {
                "render_modes": [],
                "render_fps": env.metadata["render_fps"],
                "dt": tau,
                "timestep": tau,
                "frame_skip": 1,
            },
            "stepping": {"mode": "lock_step", "action_delay": 0},
            "commands": COMMANDS,
        }

    def cmd_reset(self, msg: dict[str, Any]) -> dict[str, Any]:
        world = self._world(msg)
        seed, options = msg.get("seed"), msg.get("options")
        if seed is not None and (type(seed) is not int or seed < 0):
            raise RequestError("protocol", f"seed must be a non-negative int or nil, got {_short.repr(seed)}")
        if options is not None and not isinstance(options, dict):
            raise RequestError("protocol", f"options must be a map or nil, got {type(options).__name__}")
        obs, info = self.envs[world].reset(seed=seed, options=options)
        self.started[world] = True
        return {"obs": self._obs(obs), "info": info}

    def cmd_step(self, msg: dict[str, Any]) -> dict[str, Any]:
        world = self._world(msg)
        if not self.started[world]:
            raise RequestError("state", f"step before reset on world {world}")
        action = msg.get("action")
        if isinstance(action, np.ndarray) and action.shape == () and action.dtype.kind in "iu":
            action = int(action)
        n = int(self.envs[world].action_space.n)
        if type(action) is not int or not 0 <= action < n:
            raise RequestError("invalid_action", f"action {_short.repr(action)} is not an int in [0, {n})")
        obs, reward, terminated, truncated, info = self.envs[world].step(action)
        return {
            "obs": self._obs(obs),
            "reward": float(reward),
            "terminated": bool(terminated),
            "truncated": bool(truncated),
            "info": info,
        }

    def cmd_render(self, msg: dict[str, Any]) -> dict[str, Any]:
        self._world(msg)
        return {"frame": None}  # no render modes: headless, like a bridge without a camera

    def cmd_close(self, msg: dict[str, Any]) -> dict[str, Any]:
        self.running = False
        return {}


# ---------------------------------------------------------------- process


def write_launch_info(path: str, endpoint: str, worlds: int) -> None:
    doc = {
        "format": "remoteenv-launch/1",
        "scene": os.path.abspath(__file__),
        "env_id": "CartPole-v1",
        "host": socket.gethostname(),
        "launcher_pid": os.getpid(),
        "worlds_per_instance": worlds,
        "render_mode": None,
        "stepping": {"real_time": False, "real_time_factor": 1.0, "action_delay": 0},
        "instances": [{"instance": 0, "endpoint": endpoint, "pid": os.getpid(), "curve_server_key": None}],
        "curve_client_secret_key_file": None,
    }
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "x") as f:  # exclusive: never write through a planted file
        json.dump(doc, f, indent=2)
    os.replace(tmp, path)


def serve(out: str, worlds: int, transport: str, flaw: str | None) -> None:
    bridge = CartPoleBridge(worlds, flaw)
    private_dir = tempfile.mkdtemp(prefix="cartpole-bridge-") if transport == "ipc" else None
    sock = zmq.Context.instance().socket(zmq.ROUTER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
    sock.bind(f"ipc://{private_dir}/sim-0.sock" if private_dir else "tcp://127.0.0.1:*")
    parent = os.getppid()
    try:
        write_launch_info(out, sock.getsockopt_string(zmq.LAST_ENDPOINT), worlds)
        while bridge.running:
            if not sock.poll(250):
                if os.getppid() != parent:
                    break  # whoever started us is gone: do not linger
                continue
            parts = sock.recv_multipart()
            reply = bridge.answer(parts[-1]) if len(parts) == 2 else error(-1, "protocol", "one frame per message")
            if reply is not None:
                sock.send_multipart([parts[0], pack(reply)])
    finally:
        sock.close(linger=0)
        if private_dir:
            shutil.rmtree(private_dir, ignore_errors=True)
        if os.path.exists(out):
            os.unlink(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="launch-info file to write")
    parser.add_argument("--worlds", type=int, default=1)
    parser.add_argument("--transport", choices=["tcp", "ipc"], default="tcp")
    parser.add_argument("--flaw", choices=FLAWS, default=None, help="break one rule on purpose (for tests)")
    args = parser.parse_args()

    def _stop(signum: int, _frame: Any) -> None:
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, _stop)
    serve(os.path.abspath(args.out), args.worlds, args.transport, args.flaw)


if __name__ == "__main__":
    main()
