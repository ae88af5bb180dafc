"""Reading files at paths a user (or a launch-info file) named, without being
stalled or flooded.

Used on both sides (launch-info files, key files, delay traces). A file is
opened with ``O_NONBLOCK`` (opening a FIFO with no writer, or a device,
never waits) and ``O_NOFOLLOW`` when asked, must be a regular file (checked
on the open descriptor with ``fstat``, so nothing can be swapped in between),
and is read up to a size bound: a larger file is refused, not truncated.
JSON is parsed with its nesting bounded (:func:`read_json`), so a deeply
nested document is a clear error rather than a ``RecursionError``.
"""

from __future__ import annotations

import json
import os
import re
import stat
from typing import Any

#: Deepest nesting of arrays and objects :func:`read_json` accepts.
MAX_JSON_DEPTH = 32


class UnreadableFile(ValueError):
    """A file cannot be read as asked: not a regular file, too large, or badly formed JSON.
    (``OSError`` from opening it passes through unchanged.)"""


def read_bytes(path: str | os.PathLike[str], limit: int, *, what: str = "file", follow: bool = True) -> bytes:
    """The content of the regular file ``path``, at most ``limit`` bytes.

    Raises :class:`UnreadableFile` for anything but a regular file (a FIFO, a
    device such as ``/dev/zero``, a directory) or a file longer than
    ``limit``, and ``OSError`` when it cannot be opened. ``follow=False``
    refuses a symlink at ``path`` itself. ``what`` names the file in messages.
    """
    path = os.fspath(path)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if not follow:
        flags |= getattr(os, "O_NOFOLLOW", 0)
    fd = os.open(path, flags)
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise UnreadableFile(f"{what} {path} is not a regular file (a FIFO, device or directory cannot be read)")
        if info.st_size > limit:
            raise UnreadableFile(f"{what} {path} holds {info.st_size} bytes, more than the {limit} allowed")
        chunks = []
        total = 0
        while True:
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:  # grew while we read
                raise UnreadableFile(f"{what} {path} holds more than the {limit} bytes allowed")
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_tail(path: str | os.PathLike[str], limit: int, start: int = 0, *, what: str = "file") -> bytes:
    """The last ``limit`` bytes of the regular file ``path`` from byte ``start``
    on (a log that keeps growing: its end is what matters). Opened as
    :func:`read_bytes` opens, so a FIFO or device is refused
    (:class:`UnreadableFile`), never waited on; ``OSError`` if it cannot be opened."""
    path = os.fspath(path)
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise UnreadableFile(f"{what} {path} is not a regular file (a FIFO, device or directory cannot be read)")
        os.lseek(fd, max(start, info.st_size - limit), os.SEEK_SET)
        chunks, total = [], 0
        while total < limit:
            chunk = os.read(fd, limit - total)
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_text(path: str | os.PathLike[str], limit: int, *, what: str = "file", follow: bool = True) -> str:
    """:func:`read_bytes` decoded as UTF-8 (:class:`UnreadableFile` if it is not)."""
    data = read_bytes(path, limit, what=what, follow=follow)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UnreadableFile(f"{what} {os.fspath(path)} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def parse_json(text: str, *, what: str = "JSON", max_depth: int = MAX_JSON_DEPTH) -> Any:
    """``json.loads(text)``, refusing nesting deeper than ``max_depth`` before
    parsing (:class:`UnreadableFile`, as for malformed JSON)."""
    depth = _max_depth(text, max_depth)
    if depth > max_depth:
        raise UnreadableFile(f"{what} nests arrays and objects deeper than {max_depth}")
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise UnreadableFile(f"{what} is not valid JSON: {exc}") from None


def read_json(path: str | os.PathLike[str], limit: int, *, what: str = "file", max_depth: int = MAX_JSON_DEPTH) -> Any:
    """The JSON document in the regular file ``path`` (see :func:`read_bytes`
    and :func:`parse_json`)."""
    return parse_json(read_text(path, limit, what=what), what=f"{what} {os.fspath(path)}", max_depth=max_depth)


def _max_depth(text: str, stop: int) -> int:
    """The deepest bracket nesting of JSON ``text`` (brackets in strings skipped),
    or more than ``stop`` as soon as it passes ``stop``. Visits only the
    characters that matter (brackets, quotes, backslashes)."""
    depth = deepest = 0
    in_string = escaped = False
    last = -2
    for match in _SPECIAL.finditer(text):
        ch, at = match.group(), match.start()
        if in_string:
            if ch == "\\":
                escaped = not (escaped and at == last + 1)
                last = at
            elif ch == '"' and not (escaped and at == last + 1):
                in_string = False
            else:
                escaped = False
            continue
        if ch == '"':
            in_string, escaped = True, False
        elif ch in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > stop:
                    return deepest
        elif ch in "]}":
            depth -= 1
    return deepest


_SPECIAL = re.compile(r'["\\\[\]{}]')


__all__ = ["MAX_JSON_DEPTH", "UnreadableFile", "parse_json", "read_bytes", "read_json", "read_tail", "read_text"]
