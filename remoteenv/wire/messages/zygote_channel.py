"""The control channel between a launcher and its zygote (a pre-imported process that forks sims).

Used on both sides: the agent's :mod:`remoteenv.agent.launch.zygote` sends fork
requests, the zygote (:mod:`remoteenv.sim.process.zygote`) answers them. This is not
the sim protocol of :mod:`remoteenv.wire.protocol` (a forked sim speaks that
one, as every sim does); it only starts processes and reports their exits.

Transport: a Unix ``SOCK_SEQPACKET`` socketpair (one message per packet, end
of file when the peer is gone). Every message is one msgpack map of at most
:data:`MAX_CONTROL_BYTES`, with up to :data:`MAX_FDS` file descriptors riding
along as ``SCM_RIGHTS``. A truncated message, one with more descriptors, or a
map that does not match its kind below is refused (:class:`ProtocolError`) and
its descriptors are closed.

Messages (``kind`` and fields):

- ``ready`` (zygote → launcher, once, after its imports): ``pid`` (int),
  ``failed`` (list of str: modules it could not import).
- ``fork`` (launcher → zygote): ``argv`` (a non-empty list of str: the scene
  script and its arguments, as ``python`` would get them), ``cwd`` (str, an
  absolute path), ``pipe`` (bool). No string may hold a NUL character (no
  command line or path can).
  Descriptors: the child's stdout, its stderr, and with ``pipe`` the sim's end
  of the launcher's socketpair (the child appends ``--pipe-fd N`` to ``argv``).
- ``forked`` (zygote → launcher): ``pid`` (int). Descriptors: the launcher's
  end of the child's status channel (a socketpair of its own, whose only
  message is ``exit``) and a pidfd of the child.
- ``refused`` (zygote → launcher): ``reason`` (str); the launcher starts the
  sim the plain way instead.
- ``exit`` (zygote → launcher, on a child's status channel, once):
  ``returncode`` (int, as :attr:`subprocess.Popen.returncode`: negative for a signal).
"""

from __future__ import annotations

import array
import os
import socket
from dataclasses import dataclass
from typing import Any

from remoteenv.wire.protocol import pack, unpack
from remoteenv.wire.wire_errors import ProtocolError, short_repr

#: Largest message, bytes (below the default send buffer of a Unix socket).
MAX_CONTROL_BYTES = 1 << 17
#: Most descriptors one message carries.
MAX_FDS = 4
#: Most entries of a fork request's ``argv``.
MAX_ARGV = 4096
_KINDS = frozenset({"ready", "fork", "forked", "refused", "exit"})
_FD = array.array("i")
_CLOEXEC = getattr(socket, "MSG_CMSG_CLOEXEC", 0)


def channel_pair() -> tuple[socket.socket, socket.socket]:
    """A fresh control (or status) channel: a ``SOCK_SEQPACKET`` socketpair."""
    return socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)


def send_message(sock: socket.socket, message: dict[str, Any], fds: list[int] | tuple[int, ...] = ()) -> None:
    """Send ``message`` (with ``fds``) as one packet. Raises ``ValueError`` for
    one above :data:`MAX_CONTROL_BYTES` or :data:`MAX_FDS`, ``OSError`` if the peer is gone."""
    frame = pack(message)
    if len(frame) > MAX_CONTROL_BYTES or len(fds) > MAX_FDS:
        raise ValueError(f"a control message of {len(frame)} bytes and {len(fds)} descriptors is over the limits")
    if fds:
        socket.send_fds(sock, [frame], list(fds))
    else:
        sock.send(frame)


def receive_message(sock: socket.socket, flags: int = 0) -> tuple[dict[str, Any], list[int]] | None:
    """Receive one packet: ``(message, descriptors)``, or None at end of file.

    The caller owns the descriptors. Raises :class:`ProtocolError` (having
    closed them) for a truncated packet or one that is not a known kind's map,
    ``BlockingIOError`` with ``MSG_DONTWAIT`` when nothing is there."""
    # Not socket.recv_fds: it drops ``flags``. Received descriptors are close-on-exec.
    data, ancdata, msg_flags, _ = sock.recvmsg(
        MAX_CONTROL_BYTES + 1, socket.CMSG_SPACE(MAX_FDS * _FD.itemsize), flags | _CLOEXEC
    )
    fds = _descriptors(ancdata)
    try:
        if not data and not fds:
            return None
        if msg_flags & (socket.MSG_TRUNC | socket.MSG_CTRUNC) or len(data) > MAX_CONTROL_BYTES:
            raise ProtocolError("a truncated control message (too long, or too many descriptors)")
        message = unpack(data, max_items=MAX_ARGV)
        if not isinstance(message, dict) or message.get("kind") not in _KINDS:
            raise ProtocolError(f"not a control message: {short_repr(message)}")
    except BaseException:
        close_fds(fds)
        raise
    return message, fds


def _descriptors(ancdata: list[tuple[int, int, bytes]]) -> list[int]:
    fds = array.array("i")
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
            fds.frombytes(data[: len(data) - len(data) % fds.itemsize])
    return list(fds)


def close_fds(fds: list[int]) -> None:
    """Close every descriptor of ``fds``, ignoring ones closed already."""
    for fd in fds:
        try:
            os.close(fd)
        except OSError:
            pass


@dataclass(frozen=True)
class ForkRequest:
    """A checked ``fork`` message (see the module docstring)."""

    argv: list[str]
    cwd: str
    pipe: bool

    @property
    def fd_count(self) -> int:
        """How many descriptors come with it: stdout, stderr and, with ``pipe``, the pipe."""
        return 3 if self.pipe else 2

    def to_message(self) -> dict[str, Any]:
        return {"kind": "fork", "argv": list(self.argv), "cwd": self.cwd, "pipe": self.pipe}


def fork_request(message: dict[str, Any], fds: list[int]) -> ForkRequest:
    """The :class:`ForkRequest` in ``message``; :class:`ProtocolError` if it is
    not a well-formed ``fork`` message with the right number of ``fds``."""
    argv, cwd, pipe = message.get("argv"), message.get("cwd"), message.get("pipe")
    if (
        message.get("kind") != "fork"
        or not isinstance(argv, list)
        or not argv
        or not all(isinstance(a, str) for a in argv)
        or not isinstance(cwd, str)
        or not os.path.isabs(cwd)
        or not isinstance(pipe, bool)
        or any("\0" in text for text in (*argv, cwd))
    ):
        raise ProtocolError(f"a malformed fork request: {short_repr(message)}")
    request = ForkRequest(argv, cwd, pipe)
    if len(fds) != request.fd_count:
        raise ProtocolError(f"a fork request came with {len(fds)} descriptors, expected {request.fd_count}")
    return request


def int_field(message: dict[str, Any], kind: str, name: str) -> int:
    """``message[name]`` of a ``kind`` message, an int; :class:`ProtocolError` otherwise."""
    value = message.get(name)
    if message.get("kind") != kind or isinstance(value, bool) or not isinstance(value, int):
        raise ProtocolError(f"expected a {kind!r} message with an int {name!r}, got {short_repr(message)}")
    return value


__all__ = [
    "MAX_CONTROL_BYTES",
    "MAX_FDS",
    "ForkRequest",
    "channel_pair",
    "close_fds",
    "fork_request",
    "int_field",
    "receive_message",
    "send_message",
]
