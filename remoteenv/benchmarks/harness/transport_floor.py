"""The floors under a remote step: bare pyzmq + msgpack and a bare socketpair +
msgpack round trips with Reacher-sized messages, each to an echo child process.

Agent side (benchmarks only); :mod:`remoteenv.benchmarks.throughput` reports them.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import msgpack
import zmq

from remoteenv.benchmarks.harness.timing import timed

#: What each echo server answers: the size and shape of a Reacher step reply.
_REPLY_BODY = {
    "obs": b"\0" * 80,
    "reward": 0.5,
    "terminated": False,
    "truncated": False,
    "info": {"reward_dist": 0.1, "reward_ctrl": 0.2},
}


def _echo_server(address: str) -> None:
    """Child process of :func:`zmq_floor`: answer each msgpack request with a step-sized reply."""
    sock: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.ROUTER)
    sock.bind(address)
    while True:
        ident, frame = sock.recv_multipart()
        msg = msgpack.unpackb(frame)
        if msg["cmd"] == "close":
            sock.send_multipart([ident, frame])
            break
        sock.send_multipart([ident, msgpack.packb({"seq": msg["seq"], "ok": True, **_REPLY_BODY})])
    sock.close(linger=0)


def zmq_floor(duration: float) -> float:
    """Round trips per second of bare pyzmq DEALER/ROUTER + msgpack over ipc, with
    messages the size of a Reacher step: what any request/reply env costs at least."""
    workdir = tempfile.mkdtemp(prefix="remoteenv-bench-")
    address = f"ipc://{os.path.join(workdir, 'echo.sock')}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"from remoteenv.benchmarks.harness.transport_floor import _echo_server; _echo_server({address!r})",
        ]
    )
    sock: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(address)
    try:

        def step(i: int) -> None:
            sock.send(msgpack.packb({"seq": i, "cmd": "step", "action": b"\0" * 8}))
            msgpack.unpackb(sock.recv())

        step(0)  # waits for the server to bind
        rate = timed(step, duration)
        sock.send(msgpack.packb({"seq": -1, "cmd": "close"}))
        sock.recv()
        return rate
    finally:
        sock.close(linger=0)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        for f in os.listdir(workdir):
            os.unlink(os.path.join(workdir, f))
        os.rmdir(workdir)


def _pipe_echo_server(fd: int) -> None:
    """Child process of :func:`pipe_floor`: the same echo over a socketpair, blocking reads."""
    import socket

    sock = socket.socket(fileno=fd)
    while True:
        frame = sock.recv(65536)
        if not frame:
            break
        msg = msgpack.unpackb(frame)
        sock.sendall(msgpack.packb({"seq": msg["seq"], "ok": True, **_REPLY_BODY}))
    sock.close()


def pipe_floor(duration: float) -> float:
    """Round trips per second of a bare Unix socketpair + msgpack with Reacher-sized
    messages and plain blocking reads (no busy-waiting): the floor of the local pipe."""
    import socket

    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"from remoteenv.benchmarks.harness.transport_floor import _pipe_echo_server; _pipe_echo_server({theirs.fileno()})",
        ],
        pass_fds=(theirs.fileno(),),
    )
    theirs.close()
    try:

        def step(i: int) -> None:
            ours.sendall(msgpack.packb({"seq": i, "cmd": "step", "action": b"\0" * 8}))
            msgpack.unpackb(ours.recv(65536))

        return timed(step, duration)
    finally:
        ours.close()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
