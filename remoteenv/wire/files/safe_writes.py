"""Writing files at paths a user chose or others can reach, without being tricked.

Used on both sides (launch-info files, ready files, key files). A file is
first created under a random name in the target directory with
``O_CREAT | O_EXCL | O_NOFOLLOW`` (a name planted in advance, symlink or
not, makes the creation fail instead of being followed), filled, given its
mode through the open descriptor, and then renamed over the target with
``os.replace`` (which replaces a symlink at the target instead of writing
through it). Readers see no file or the whole of it.
"""

from __future__ import annotations

import os
import secrets

_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def create_new(path: str | os.PathLike[str], text: str, mode: int = 0o644) -> None:
    """Create ``path`` holding ``text`` with ``mode`` (not filtered by the umask);
    raise ``FileExistsError`` if anything, a symlink included, is there already."""
    fd = os.open(os.fspath(path), _FLAGS, 0o600)
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "w") as f:
            fd = -1
            f.write(text)
    except BaseException:
        if fd >= 0:
            os.close(fd)
        _unlink_quietly(path)
        raise


def write_atomic(path: str | os.PathLike[str], text: str, mode: int = 0o644) -> None:
    """Write ``text`` to ``path`` atomically: a fresh file under a random name
    beside it (see the module docstring), then renamed over ``path``."""
    path = os.fspath(path)
    directory, name = os.path.split(os.path.abspath(path))
    tmp = os.path.join(directory, f".{name}.{secrets.token_hex(8)}.tmp")
    create_new(tmp, text, mode)
    try:
        os.replace(tmp, path)
    except BaseException:
        _unlink_quietly(tmp)
        raise


def write_user_file(path: str | os.PathLike[str], text: str, what: str) -> None:
    """:func:`write_atomic` for a file at a path the user gave (mode 0644): an
    OSError names that path and ``what`` it was to hold, never the temporary
    file beside it, and says what to do when its folder does not exist."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FileNotFoundError(
            f"cannot save the {what} to {path}: the folder {folder} does not exist; create it first"
        )
    try:
        write_atomic(path, text, 0o644)
    except OSError as exc:
        raise type(exc)(f"cannot save the {what} to {path}: {exc.strerror or exc}") from None


def _unlink_quietly(path: str | os.PathLike[str]) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


__all__ = ["create_new", "write_atomic", "write_user_file"]
