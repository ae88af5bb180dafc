"""ZeroMQ CURVE keys: generate key pairs, save and load them as Z85 text.

Used on both sides. A sim that binds beyond loopback holds a *server* key
pair; an agent that drives it holds the server's public key and a *client*
key pair whose public half the sim has on its list of allowed clients. Only a
holder of both can talk to the sim; anyone else's connection is dropped during
the CURVE handshake and gets nothing.

Key files are text: comment lines starting with ``#`` and one line holding a
40-character Z85 key. Secret key files are created with mode 0600 and never
overwritten; no key file is written through a symlink
(:func:`remoteenv.wire.files.safe_writes.create_new`). A file of allowed client keys holds one public key per line.
Key files are read as :mod:`remoteenv.wire.files.file_reads` reads any file a
user names: never blocking, regular files only, at most
:data:`MAX_KEY_FILE_BYTES`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass

import zmq
from zmq.utils import z85

from remoteenv.wire.files.file_reads import read_bytes
from remoteenv.wire.files.safe_writes import create_new

#: Length of a Z85-encoded 32-byte CURVE key.
Z85_KEY_LENGTH = 40
#: Largest key file read (bytes): some 25,000 keys of one line each.
MAX_KEY_FILE_BYTES = 1 << 20


@dataclass(frozen=True)
class KeyPair:
    """A CURVE key pair, both halves Z85-encoded (40 ASCII bytes each)."""

    public: bytes
    secret: bytes

    def __repr__(self) -> str:  # never print a secret key by accident
        return f"KeyPair(public={self.public!r}, secret=<hidden>)"


def generate_keypair() -> KeyPair:
    """A fresh random CURVE key pair (needs libzmq built with CURVE)."""
    if not zmq.has("curve"):
        raise RuntimeError("this libzmq has no CURVE support; install a pyzmq wheel built with libsodium")
    public, secret = zmq.curve_keypair()
    return KeyPair(public=public, secret=secret)


def public_from_secret(secret: bytes) -> bytes:
    """The public key belonging to Z85 secret key ``secret``."""
    return zmq.curve_public(check_key(secret, "secret key"))


def check_key(key: bytes | str, what: str = "key") -> bytes:
    """Return ``key`` as bytes if it is a well-formed Z85 CURVE key, else raise ValueError."""
    if isinstance(key, str):
        key = key.encode("ascii", "replace")
    key = key.strip()
    if len(key) != Z85_KEY_LENGTH:
        raise ValueError(f"a Z85 CURVE {what} has {Z85_KEY_LENGTH} characters, got {len(key)}")
    try:
        if len(z85.decode(key)) != 32:
            raise ValueError
    except Exception:
        raise ValueError(f"{what} is not valid Z85 text") from None
    return key


def _write_new(path: str, text: str, mode: int) -> None:
    # Exclusive creation: a planted file or symlink at ``path`` makes this fail.
    create_new(path, text, mode)


def write_secret_key(path: str | os.PathLike[str], secret: bytes) -> None:
    """Write ``secret`` to a new file readable by its owner only (0600).

    Raises FileExistsError rather than overwrite an existing file."""
    key = check_key(secret, "secret key").decode()
    _write_new(os.fspath(path), f"# remoteenv CURVE secret key: keep private\n{key}\n", 0o600)


def write_public_keys(path: str | os.PathLike[str], keys: Iterable[bytes]) -> None:
    """Write public keys, one per line, to a new file (0644)."""
    lines = [check_key(k, "public key").decode() for k in keys]
    _write_new(os.fspath(path), "# remoteenv CURVE public key(s)\n" + "".join(f"{k}\n" for k in lines), 0o644)


def read_keys(path: str | os.PathLike[str]) -> list[bytes]:
    """Every key in a key file (comment and blank lines skipped), each checked.

    Raises ``ValueError`` (:class:`~remoteenv.wire.files.file_reads.UnreadableFile`
    for a file that is not regular or is too large) naming the file, and
    ``OSError`` when it cannot be opened."""
    keys = []
    data = read_bytes(path, MAX_KEY_FILE_BYTES, what="key file")
    for n, line in enumerate(data.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith(b"#"):
            continue
        try:
            keys.append(check_key(line))
        except ValueError as exc:
            raise ValueError(f"{os.fspath(path)}, line {n}: {exc}") from None
    return keys


def read_key(path: str | os.PathLike[str]) -> bytes:
    """The single key in a key file."""
    keys = read_keys(path)
    if len(keys) != 1:
        raise ValueError(f"{os.fspath(path)} should hold exactly one key, found {len(keys)}")
    return keys[0]


def save_keypair(directory: str | os.PathLike[str], name: str) -> tuple[str, str]:
    """Generate a key pair and save it as ``<name>.key`` (public) and
    ``<name>.key_secret`` (0600) in ``directory``. Returns both paths."""
    directory = os.fspath(directory)
    os.makedirs(directory, exist_ok=True)
    pair = generate_keypair()
    public_path = os.path.join(directory, f"{name}.key")
    secret_path = os.path.join(directory, f"{name}.key_secret")
    write_secret_key(secret_path, pair.secret)
    write_public_keys(public_path, [pair.public])
    return public_path, secret_path


def load_keypair(secret_path: str | os.PathLike[str]) -> KeyPair:
    """Load a key pair from its secret key file (the public half is derived)."""
    secret = read_key(secret_path)
    return KeyPair(public=public_from_secret(secret), secret=secret)


__all__ = [
    "MAX_KEY_FILE_BYTES",
    "KeyPair",
    "check_key",
    "generate_keypair",
    "load_keypair",
    "public_from_secret",
    "read_key",
    "read_keys",
    "save_keypair",
    "write_public_keys",
    "write_secret_key",
]
