"""The delay file: how a launch's delay specs reach its sim.

Both processes use this module: a launcher (the local one in the agent
process, or a Ray actor on the sim's node) writes the file, the sim reads it
at start (``--delay-file``). A delay spec may hold up to
:data:`~remoteenv.wire.delays.delay_specs.MAX_VALUES` values (a recorded
:class:`~remoteenv.wire.delays.delay_specs.Trace`), far more than a command line takes
(Linux caps one argument at 128 KiB), so specs never travel as arguments.

Format: UTF-8 JSON, one map with any of the keys ``"action_delay"``,
``"obs_delay"`` (ticks) and ``"link_delay"`` (seconds), each the wire form
of a spec (:meth:`~remoteenv.wire.delays.delay_specs.DelaySpec.to_wire`), and
``"channel"``: lock-step's delivery rules and delayed rewards
(:meth:`~remoteenv.wire.delays.channel_rules.ChannelRules.to_wire`), present
only when they differ from the default and a lock-step delay is there for
them to act on. A delay that is always 0 is left out; a launch without
delays writes no file.

Writing (:func:`write_delay_file`): created exclusively (a file or symlink
already at the path makes it fail), mode 0600, in the launcher's private dir
next to the sim's other files (``sim-<instance>.delays.json``), so it is
removed with them.

Reading (:func:`read_delay_file`) treats the file as hostile: opened without
following a symlink and without blocking (a FIFO there cannot stall the
sim), refused unless it is a regular file, at most
:data:`MAX_DELAY_FILE_BYTES` read, every spec rebuilt by
:func:`~remoteenv.wire.delays.delay_specs.delay_from_wire` (which checks every field).
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Mapping
from typing import Any

from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.delay_specs import MAX_VALUES, SECONDS, TICKS, DelaySpec, as_delay, delay_from_wire
from remoteenv.wire.files.file_reads import UnreadableFile, parse_json
from remoteenv.wire.files.safe_writes import create_new
from remoteenv.wire.wire_errors import ProtocolError, short_repr

#: The keys of a delay file and each one's unit.
DELAY_KEYS: dict[str, str] = {"action_delay": TICKS, "obs_delay": TICKS, "link_delay": SECONDS}
#: The key of the channel rules in a delay file.
CHANNEL_KEY = "channel"
#: Largest delay file read: three specs of two lists (values and
#: probabilities) of :data:`MAX_VALUES` numbers, 32 bytes each at most in JSON
#: (the channel rules' few bytes fit in the margin).
MAX_DELAY_FILE_BYTES = len(DELAY_KEYS) * 2 * MAX_VALUES * 32

_READ_FLAGS = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)


def delay_file_text(
    action_delay: int | DelaySpec = 0,
    obs_delay: int | DelaySpec = 0,
    link_delay: float | DelaySpec | None = None,
    channel: ChannelRules | None = None,
) -> str | None:
    """The delay file's text for these delays (``action_delay``/``obs_delay``
    in ticks, ``link_delay`` in seconds: numbers or specs) and lock-step's
    channel rules, or None when every delay is always 0. Raises ValueError
    for a delay of the wrong unit."""
    given = {"action_delay": action_delay, "obs_delay": obs_delay, "link_delay": link_delay}
    specs: dict[str, Any] = {}
    for key, value in given.items():
        if value is None:
            continue
        spec = as_delay(value, DELAY_KEYS[key])
        if not spec.is_zero:
            specs[key] = spec.to_wire()
    lock_step_delayed = "action_delay" in specs or "obs_delay" in specs
    if channel is not None and not channel.is_default and lock_step_delayed:
        specs[CHANNEL_KEY] = channel.to_wire()
    return json.dumps(specs, separators=(",", ":")) if specs else None


def write_delay_file(path: str | os.PathLike[str], text: str) -> None:
    """Create ``path`` holding ``text`` (from :func:`delay_file_text`), mode
    0600; FileExistsError if anything is at ``path`` already."""
    create_new(path, text, 0o600)


def read_delay_file(path: str | os.PathLike[str]) -> dict[str, DelaySpec | ChannelRules]:
    """The specs (and channel rules) in the delay file at ``path``, by key (see the module docstring).

    Raises ProtocolError saying what is wrong: not a regular file (a
    symlink, a FIFO, a directory), larger than :data:`MAX_DELAY_FILE_BYTES`,
    not JSON, an unknown key, or an invalid spec."""
    path = os.fspath(path)
    what = f"delay file {short_repr(path)}"
    try:
        fd = os.open(path, _READ_FLAGS)
    except OSError as exc:
        raise ProtocolError(f"cannot open {what}: {exc.strerror} (a symlink is refused)") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ProtocolError(f"{what} is not a regular file")
        if info.st_size > MAX_DELAY_FILE_BYTES:
            raise ProtocolError(f"{what} holds {info.st_size} bytes, more than {MAX_DELAY_FILE_BYTES}")
        with os.fdopen(fd, "rb") as f:
            fd = -1
            data = f.read(MAX_DELAY_FILE_BYTES + 1)
    finally:
        if fd >= 0:
            os.close(fd)
    if len(data) > MAX_DELAY_FILE_BYTES:
        raise ProtocolError(f"{what} grew beyond {MAX_DELAY_FILE_BYTES} bytes while being read")
    try:
        desc = parse_json(data.decode("utf-8"), what=what)  # nesting bounded before parsing
    except (UnicodeDecodeError, UnreadableFile) as exc:
        raise ProtocolError(f"{what} is not UTF-8 JSON: {short_repr(str(exc))}") from None
    return delays_from_map(desc, what)


def delays_from_map(desc: Any, what: str = "a delay map") -> dict[str, DelaySpec | ChannelRules]:
    """The specs of a delay file's map, each checked and of its key's unit,
    and its channel rules (:data:`CHANNEL_KEY`), checked."""
    if not isinstance(desc, Mapping):
        raise ProtocolError(f"{what} must hold a JSON map, got {type(desc).__name__}")
    known = [*DELAY_KEYS, CHANNEL_KEY]
    unknown = sorted(str(k) for k in desc if k not in known)
    if unknown:
        raise ProtocolError(f"{what} has unknown keys {short_repr(unknown[:10])}; expected some of {known}")
    specs: dict[str, DelaySpec | ChannelRules] = {}
    for key, wire in desc.items():
        if key == CHANNEL_KEY:
            try:
                specs[key] = ChannelRules.from_wire(wire)
            except ProtocolError as exc:
                raise ProtocolError(f"{what}: {exc}") from None
            continue
        try:
            specs[key] = as_delay(delay_from_wire(wire), DELAY_KEYS[key])
        except (ProtocolError, ValueError) as exc:
            raise ProtocolError(f"{what}: {key}: {exc}") from None
    return specs


__all__ = [
    "CHANNEL_KEY",
    "DELAY_KEYS",
    "MAX_DELAY_FILE_BYTES",
    "delay_file_text",
    "delays_from_map",
    "read_delay_file",
    "write_delay_file",
]
