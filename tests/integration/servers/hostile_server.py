"""A remoteenv-protocol server that completes the handshake and then lies.

Like ``gym_cartpole_server.py`` it is written from the spec alone (pyzmq,
msgpack and numpy; nothing from remoteenv) and stands in for a peer the
agent does not control: a broken robot bridge, a third-party server, a
hostile process behind a launch-info file. Its honest behaviour is a tiny
lock-step env (obs a float32 Box of shape (4,), action Discrete(2), reward
1.0, an episode ends after 3 steps) with the batch and attribute commands;
``--lie NAME`` breaks one rule of the spec, so tests can check that the
client side holds (a typed error within the deadline, bounded memory):

- handshake lies (the handshake reply itself): ``hs-worlds`` (10**9
  worlds), ``hs-dict`` (a Dict of 300,000 subspaces), ``hs-multibinary``
  (MultiBinary(10**9)), ``hs-deep`` (Tuples nested 500 deep),
  ``hs-discrete`` (Discrete(2**64 - 1)), ``hs-dtype`` (a Box of dtype
  ``V16``);
- timing and memory lies: ``trickle`` (a step is answered only by replies
  with a wrong ``seq``, every 5-40 ms, forever), ``flood`` (after the
  handshake, ``--flood`` stale frames of 30 MiB each, pushed as fast as the
  client takes them), ``big-error`` (a 30 MiB error message), ``oversize``
  (a reply of 33 MiB, above the frame limit), ``value-bomb`` (a 30 MiB reply
  of 30 million empty maps);
- reply lies (for ``step``/``step_batch``, ``render`` or ``get_attr``):
  ``no-reward``, ``reward-str``, ``flag-str``, ``obs-list``, ``obs-dtype``,
  ``obs-shape``, ``info-list``, ``reward-short`` (a reward list of 1 for n
  worlds), ``final-index`` (a ``final`` entry at position -1),
  ``final-far`` (at position n), ``columns-short`` (info columns of the
  wrong length), ``error-not-map``, ``ok-missing``, ``types-bad`` (a
  ``types`` map naming int8 for a reward of 1000), ``frame-str``,
  ``attr-missing``.

Usage: ``python hostile_server.py --out launch.json --lie NAME [--worlds K]
[--flood N]``. Binds 127.0.0.1 on an OS-chosen port, writes a launch-info
file and serves until ``close``, SIGTERM or its parent's death.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import socket
import struct
import time
from typing import Any

import msgpack
import numpy as np
import zmq

PROTOCOL_VERSION = 1
EXT_ARRAY = 1
MIB = 1 << 20
COMMANDS = [
    "handshake",
    "reset",
    "step",
    "render",
    "close",
    "reset_batch",
    "step_batch",
    "get_attr",
    "set_attr",
    "call",
]
HANDSHAKE_LIES = ("hs-worlds", "hs-dict", "hs-multibinary", "hs-deep", "hs-discrete", "hs-dtype")
TIMING_LIES = ("trickle", "flood", "big-error", "oversize", "value-bomb")
REPLY_LIES = (
    "no-reward",
    "reward-str",
    "flag-str",
    "obs-list",
    "obs-dtype",
    "obs-shape",
    "info-list",
    "reward-short",
    "final-index",
    "final-far",
    "columns-short",
    "error-not-map",
    "ok-missing",
    "types-bad",
    "frame-str",
    "attr-missing",
    "reset-obs",
    "reset-info",
)
LIES = (*HANDSHAKE_LIES, *TIMING_LIES, *REPLY_LIES)
EPISODE_STEPS = 3


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
    n = data[0]
    dtype = data[1 : 1 + n].decode("ascii")
    ndim = data[1 + n]
    shape = struct.unpack_from(f"<{ndim}Q", data, 2 + n)
    return np.frombuffer(data, dtype, math.prod(shape), 2 + n + 8 * ndim).reshape(shape).copy()


def error(seq: int, kind: str, message: str) -> dict[str, Any]:
    return {"seq": seq, "ok": False, "error": {"kind": kind, "message": message, "traceback": ""}}


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_to_wire, use_bin_type=True)


def _box(shape: tuple[int, ...], dtype: str = "<f4") -> dict[str, Any]:
    return {
        "type": "Box",
        "low": np.full(shape, -10.0, np.float32),
        "high": np.full(shape, 10.0, np.float32),
        "dtype": dtype,
    }


class Liar:
    """``worlds`` tiny worlds served honestly, except for one lie."""

    def __init__(self, worlds: int, lie: str) -> None:
        self.worlds = worlds
        self.lie = lie
        self.steps = [0] * worlds
        self.running = True

    # ------------------------------------------------------------ honest answers

    def obs(self, world: int) -> np.ndarray:
        return np.array([world, self.steps[world], 0.5, -0.5], dtype=np.float32)

    def handshake(self) -> dict[str, Any]:
        obs_space: Any = _box((4,))
        action_space: Any = {"type": "Discrete", "n": 2, "start": 0}
        num_worlds = self.worlds
        if self.lie == "hs-worlds":
            num_worlds = 10**9
        elif self.lie == "hs-dict":
            obs_space = {
                "type": "Dict",
                "spaces": {f"k{i}": {"type": "Discrete", "n": 2, "start": 0} for i in range(300_000)},
            }
        elif self.lie == "hs-multibinary":
            obs_space = {"type": "MultiBinary", "n": [10**9]}
        elif self.lie == "hs-deep":
            for _ in range(500):  # msgpack packs at most 511 levels
                obs_space = {"type": "Tuple", "spaces": [obs_space]}
        elif self.lie == "hs-discrete":
            action_space = {"type": "Discrete", "n": 2**64 - 1, "start": 0}
        elif self.lie == "hs-dtype":
            obs_space = dict(_box((4,)), dtype="V16")
        return {
            "protocol": PROTOCOL_VERSION,
            "env_id": "Hostile-v0",
            "instance": 0,
            "pid": os.getpid(),
            "num_worlds": num_worlds,
            "observation_space": obs_space,
            "action_space": action_space,
            "metadata": {
                "render_modes": ["rgb_array"],
                "render_fps": 50,
                "dt": 0.02,
                "timestep": 0.02,
                "frame_skip": 1,
            },
            "stepping": {"mode": "lock_step", "action_delay": 0},
            "commands": COMMANDS,
        }

    def reset(self, world: int) -> tuple[np.ndarray, dict[str, Any]]:
        self.steps[world] = 0
        return self.obs(world), {"episode_start": True}

    def step(self, world: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.steps[world] += 1
        done = self.steps[world] >= EPISODE_STEPS
        return self.obs(world), 1.0, done, False, {"count": self.steps[world]}

    def answer(self, msg: dict[str, Any]) -> dict[str, Any]:
        cmd = msg["cmd"]
        if cmd == "handshake":
            return self.handshake()
        if cmd == "reset":
            obs, info = self.reset(msg.get("world", 0))
            return {"obs": obs, "info": info}
        if cmd == "step":
            obs, reward, terminated, truncated, info = self.step(msg.get("world", 0))
            return {"obs": obs, "reward": reward, "terminated": terminated, "truncated": truncated, "info": info}
        if cmd == "reset_batch":
            pairs = [self.reset(w) for w in msg["worlds"]]
            return {"obs": np.stack([p[0] for p in pairs]), "info": {"maps": [p[1] for p in pairs]}}
        if cmd == "step_batch":
            return self.step_batch(msg["ops"], msg.get("worlds"))
        if cmd == "render":
            return {"frame": np.zeros((8, 8, 3), np.uint8)}
        if cmd == "get_attr":
            return {"value": 7, "callable": False}
        if cmd == "call":
            return {"result": 7}
        if cmd == "close":
            self.running = False
        return {}

    def step_batch(self, ops: list[int], worlds: list[int] | None) -> dict[str, Any]:
        worlds = list(range(len(ops))) if worlds is None else worlds
        obs, rewards, terms, truncs, infos, final = [], [], [], [], [], []
        for j, (op, w) in enumerate(zip(ops, worlds)):
            if op == 1:
                o, info = self.reset(w)
                r, term, trunc = 0.0, False, False
            else:
                o, r, term, trunc, info = self.step(w)
                if op == 3 or (op == 2 and (term or trunc)):
                    final.append([j, o, info])
                    o, info = self.reset(w)
            obs.append(o)
            rewards.append(r)
            terms.append(term)
            truncs.append(trunc)
            infos.append(info)
        count = [float(i.get("count", 0)) for i in infos]
        return {
            "obs": np.stack(obs),
            "reward": rewards,
            "terminated": terms,
            "truncated": truncs,
            "info": {"columns": {"count": [count, [True] * len(ops)]}},
            "final": final,
        }

    # ------------------------------------------------------------ lies

    def lie_about(self, cmd: str, reply: dict[str, Any]) -> dict[str, Any]:
        """The reply with this server's lie in it (``cmd``'s reply, ``ok`` and ``seq`` set)."""
        lie = self.lie
        stepping = cmd in ("step", "step_batch")
        if lie == "frame-str" and cmd == "render":
            reply["frame"] = "pixels"
        elif lie == "attr-missing" and cmd == "get_attr":
            del reply["value"]
            reply["callable"] = "no"
        elif lie == "reset-obs" and cmd in ("reset", "reset_batch"):
            reply["obs"] = reply["obs"].astype(np.float64)
        elif lie == "reset-info" and cmd in ("reset", "reset_batch"):
            reply["info"] = ["not", "a", "map"]
        elif not stepping:
            return reply
        elif lie == "no-reward":
            del reply["reward"]
        elif lie == "reward-str":
            reply["reward"] = "1.0" if cmd == "step" else ["1.0"] * len(reply["reward"])
        elif lie == "flag-str":
            reply["terminated"] = "no" if cmd == "step" else ["no"] * len(reply["terminated"])
        elif lie == "obs-list":
            reply["obs"] = reply["obs"].tolist()
        elif lie == "obs-dtype":
            reply["obs"] = reply["obs"].astype(np.float64)
        elif lie == "obs-shape":
            reply["obs"] = np.zeros((*reply["obs"].shape[:-1], 5), np.float32)
        elif lie == "info-list":
            reply["info"] = ["not", "a", "map"]
        elif lie == "reward-short" and cmd == "step_batch":
            reply["reward"] = reply["reward"][:1]
        elif lie in ("final-index", "final-far") and cmd == "step_batch":
            n = len(reply["reward"])
            reply["final"] = [[-1 if lie == "final-index" else n, np.full(4, 99.0, np.float32), {"fake": True}]]
        elif lie == "columns-short" and cmd == "step_batch":
            reply["info"] = {"columns": {"count": [[1.0], [True]]}}
        elif lie == "error-not-map":
            return {"seq": reply["seq"], "ok": False, "error": "boom"}
        elif lie == "ok-missing":
            del reply["ok"]
        elif lie == "types-bad" and cmd == "step":
            reply["reward"] = 1000
            reply["types"] = {"reward": "|i1", "info": {"count": "|u1"}}
            reply["info"]["count"] = -5
        return reply


def write_launch_info(path: str, endpoint: str, worlds: int) -> None:
    doc = {
        "format": "remoteenv-launch/1",
        "scene": os.path.abspath(__file__),
        "env_id": "Hostile-v0",
        "host": socket.gethostname(),
        "launcher_pid": os.getpid(),
        "worlds_per_instance": worlds,
        "render_mode": "rgb_array",
        "stepping": {"real_time": False, "real_time_factor": 1.0, "action_delay": 0},
        "instances": [{"instance": 0, "endpoint": endpoint, "pid": os.getpid(), "curve_server_key": None}],
        "curve_client_secret_key_file": None,
    }
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "x") as f:
        json.dump(doc, f)
    os.replace(tmp, path)


class Server:
    def __init__(self, out: str, worlds: int, lie: str, flood: int) -> None:
        self.liar = Liar(worlds, lie)
        self.flood = flood
        self.sock = zmq.Context.instance().socket(zmq.ROUTER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.SNDHWM, 2)  # a flood blocks here (below) instead of filling this process
        self.sock.setsockopt(zmq.ROUTER_MANDATORY, 1)
        self.sock.bind("tcp://127.0.0.1:*")
        self.out = out
        self.parent = os.getppid()
        #: Peers and seqs of steps answered by a trickle of wrong-seq replies.
        self.trickling: list[tuple[bytes, int]] = []

    def send(self, peer: bytes, reply: Any) -> None:
        frame = reply if isinstance(reply, bytes) else pack(reply)
        while True:
            try:
                self.sock.send_multipart([peer, frame], flags=zmq.NOBLOCK, copy=False)
                return
            except zmq.Again:  # the client's queue is full: wait (a parent that is gone ends us)
                if os.getppid() != self.parent:
                    raise SystemExit(0) from None
                time.sleep(0.01)
            except zmq.ZMQError:  # the peer went away
                return

    def serve(self) -> None:
        write_launch_info(self.out, self.sock.getsockopt_string(zmq.LAST_ENDPOINT), self.liar.worlds)
        liar = self.liar
        next_trickle = 0.0
        while liar.running:
            wait_ms = 250 if not self.trickling else random.randint(5, 40)
            if not self.sock.poll(wait_ms):
                if os.getppid() != self.parent:
                    return
                if self.trickling and time.monotonic() >= next_trickle:
                    for peer, seq in self.trickling:
                        self.send(peer, {"seq": seq + 1000, "ok": True, "obs": None})
                    next_trickle = time.monotonic() + random.uniform(0.005, 0.04)
                continue
            parts = self.sock.recv_multipart()
            peer, frame = parts[0], parts[-1]
            msg: Any = None
            try:
                msg = msgpack.unpackb(frame, raw=False, ext_hook=_from_wire, strict_map_key=False)
                seq, cmd = msg["seq"], msg["cmd"]
                if type(seq) is not int or cmd not in COMMANDS:
                    raise ValueError("not a request this server knows")
            except Exception as exc:  # the honest part: a protocol error (seq -1 when there is no seq)
                seq = msg.get("seq") if isinstance(msg, dict) else None
                self.send(
                    peer, error(seq if type(seq) is int else -1, "protocol", f"bad request: {type(exc).__name__}")
                )
                continue
            try:
                self.answer(peer, seq, cmd, msg)
            except Exception as exc:
                self.send(peer, error(seq, "protocol", f"bad arguments: {type(exc).__name__}"))

    def answer(self, peer: bytes, seq: int, cmd: str, msg: dict[str, Any]) -> None:
        liar, lie = self.liar, self.liar.lie
        stepping = cmd in ("step", "step_batch")
        if lie == "trickle" and stepping:
            self.trickling.append((peer, seq))
            return
        if lie == "big-error" and stepping:
            self.send(
                peer,
                {"seq": seq, "ok": False, "error": {"kind": "scene", "message": "x" * (30 * MIB), "traceback": ""}},
            )
            return
        if lie == "oversize" and stepping:
            self.send(peer, {"seq": seq, "ok": True, "padding": b"\0" * (33 * MIB)})
            return
        if lie == "value-bomb" and stepping:
            # {"seq": seq, "ok": true, "bomb": [{}, {}, ...]}: 30 MiB of one-byte empty maps.
            n = 30 * MIB
            head = b"\x83" + pack("seq") + pack(seq) + pack("ok") + pack(True) + pack("bomb")
            self.send(peer, head + b"\xdd" + struct.pack(">I", n) + b"\x80" * n)
            return
        reply = {"seq": seq, "ok": True, **liar.answer(msg)}
        self.send(peer, liar.lie_about(cmd, reply))
        if lie == "flood" and cmd == "handshake":
            stale = pack({"seq": seq + 10**6, "ok": True, "padding": b"\1" * (30 * MIB)})
            for _ in range(self.flood):
                self.send(peer, stale)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="launch-info file to write")
    parser.add_argument("--lie", choices=LIES, required=True)
    parser.add_argument("--worlds", type=int, default=1)
    parser.add_argument("--flood", type=int, default=200, help="stale 30 MiB frames the flood lie sends")
    args = parser.parse_args()

    def _stop(signum: int, _frame: Any) -> None:
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, _stop)
    out = os.path.abspath(args.out)
    server = Server(out, args.worlds, args.lie, args.flood)
    try:
        server.serve()
    finally:
        server.sock.close(linger=0)
        if os.path.exists(out):
            os.unlink(out)


if __name__ == "__main__":
    main()
