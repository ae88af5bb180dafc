"""Removing the private dirs remoteenv made, and files in them, without acting on anything else.

Used on both sides (the launcher's ``stop_all``, a sim tidying up for a dead
agent) and by two standalone processes that load this file by path (the
sim's orphan guard, the agent's dir reaper): it imports only the standard
library.

A dir is known by its path and its *identity*, ``(st_dev, st_ino)`` of the
dir remoteenv made, taken right after making it (:func:`identity`). Nothing
here acts through a path it did not make:

- the dir is opened relative to its parent with ``O_DIRECTORY | O_NOFOLLOW
  | O_NONBLOCK``: a symlink, a FIFO, a device or a regular file planted at
  the path is refused by the open itself, which never waits;
- what was opened must be a directory of this user with the identity
  recorded (a dir swapped in under the same name is someone else's);
- entries are removed through the open dir's descriptor
  (``os.unlink(name, dir_fd=fd)`` removes a symlink, never its target;
  subdirectories are opened the same way, never followed), and the dir
  itself with ``rmdir(name, dir_fd=parent)`` once its identity is checked again.

Every function returns quietly when something is not as expected: tidying
up is best effort, and refusing is the safe outcome.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager

#: ``(st_dev, st_ino)`` of a dir remoteenv made.
DirId = tuple[int, int]

_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
#: Opening a dir entry: refuses symlinks and non-directories and never waits (a FIFO).
_OPEN_DIR = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK | _CLOEXEC
#: Opening the parent of a private dir (the user's TMPDIR): a symlink on the way is the user's own.
_OPEN_PARENT = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | os.O_NONBLOCK | _CLOEXEC
#: Deepest subdirectory removed (remoteenv's dirs are flat; deeper is left alone).
MAX_DEPTH = 16


def identity(path: str) -> DirId | None:
    """The identity of the dir at ``path`` (not followed if a symlink), or
    None if it is not a directory of this user."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid():
        return None
    return (st.st_dev, st.st_ino)


def format_id(dir_id: DirId | None) -> str:
    """``dir_id`` as ``"dev:ino"`` ("" for None), for a command line or a record."""
    return "" if dir_id is None else f"{dir_id[0]}:{dir_id[1]}"


def parse_id(text: str) -> DirId | None:
    """The identity :func:`format_id` wrote (None for "" or anything malformed)."""
    dev, sep, ino = text.partition(":")
    if not sep or not dev.isdigit() or not ino.isdigit():
        return None
    return (int(dev), int(ino))


def _is_ours(fd: int, dir_id: DirId | None) -> bool:
    st = os.fstat(fd)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid():
        return False
    return dir_id is None or (st.st_dev, st.st_ino) == tuple(dir_id)


@contextmanager
def _opened(path: str, dir_id: DirId | None) -> Iterator[tuple[int, int, str] | None]:
    """``(parent fd, dir fd, name)`` of the dir at ``path`` if it is ours (see
    the module docs), else None; both descriptors are closed afterwards."""
    parent_path, name = os.path.split(os.path.abspath(path))
    fds: list[int] = []
    try:
        try:
            fds.append(os.open(parent_path or "/", _OPEN_PARENT))
            fds.append(os.open(name, _OPEN_DIR, dir_fd=fds[0]))
        except OSError:
            yield None
            return
        yield (fds[0], fds[1], name) if _is_ours(fds[1], dir_id) else None
    finally:
        for fd in fds:
            os.close(fd)


def _clear(fd: int, depth: int = 0) -> None:
    """Remove everything in the open dir ``fd``, through descriptors only."""
    entries = _entries(fd)
    for name, is_dir in entries:
        if is_dir and depth < MAX_DEPTH:
            try:
                sub = os.open(name, _OPEN_DIR, dir_fd=fd)
            except OSError:  # swapped for something else since the listing: unlink that instead
                _unlink(name, fd)
                continue
            try:
                _clear(sub, depth + 1)
            finally:
                os.close(sub)
            try:
                os.rmdir(name, dir_fd=fd)
            except OSError:
                pass
        elif not is_dir:
            _unlink(name, fd)


def _entries(fd: int) -> list[tuple[str, bool]]:
    """``(name, is a directory)`` of each entry of the open dir ``fd`` (symlinks not followed)."""
    try:
        with os.scandir(fd) as it:
            return [(e.name, e.is_dir(follow_symlinks=False)) for e in it]
    except OSError:
        return []


def _unlink(name: str, dir_fd: int) -> None:
    try:
        os.unlink(name, dir_fd=dir_fd)
    except OSError:
        pass


def _remove_opened(parent: int, fd: int, name: str) -> None:
    """Empty the open dir ``fd`` and remove it from ``parent`` if ``name`` still names it."""
    _clear(fd)
    try:
        st = os.lstat(name, dir_fd=parent)
        if os.path.samestat(st, os.fstat(fd)):
            os.rmdir(name, dir_fd=parent)
    except OSError:
        pass


def remove_dir(path: str, dir_id: DirId | None) -> bool:
    """Remove the private dir ``path`` and everything in it, if it is the dir
    ``dir_id`` names (None: any dir of this user; no symlink is ever followed).
    True if it was removed (or was never there as ours: nothing left to do)."""
    with _opened(path, dir_id) as opened:
        if opened is None:
            return False
        _remove_opened(*opened)
    return True


def remove_files(path: str, dir_id: DirId | None, prefix: str, others: str) -> None:
    """Remove the entries named ``prefix...`` from the private dir ``path`` (if
    it is the dir ``dir_id`` names); then, if no entry named ``others...`` is
    left, the dir and what remains in it."""
    with _opened(path, dir_id) as opened:
        if opened is None:
            return
        parent, fd, name = opened
        for entry, _is_dir in _entries(fd):
            if entry.startswith(prefix):
                _unlink(entry, fd)
        if not any(entry.startswith(others) for entry, _is_dir in _entries(fd)):
            _remove_opened(parent, fd, name)


__all__ = ["MAX_DEPTH", "DirId", "format_id", "identity", "parse_id", "remove_dir", "remove_files"]
