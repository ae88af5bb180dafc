"""The file of one recorded real-time episode, which the exact twin replays.

Runs in the agent process. A recording is a JSON object (written
atomically, never through a symlink; read through
:mod:`remoteenv.wire.files.file_reads` with a size bound, every field checked):

``format``           ``"remoteenv.real_time_recording"``.
``version``          2 (this reader also reads 1, which has no ``env`` and
                     no ``link_delays``; it refuses a version it does not know).
``env_id``           the env id the episode ran in.
``env``              the env it ran in: ``{"kwargs", "max_episode_steps",
                     "real_time_factor", "link_delay", "unrecorded"}``
                     (:class:`~remoteenv.latency.twin.recorded_env.RecordedEnv`),
                     or null when unknown.
``real_time_mode``   ``"elastic"`` or ``"fixed_step"``.
``seed``             the seed of the episode's reset or of the last seeded
                     reset before it (None: never seeded).
``resets_after_seed``  unseeded resets from that seeded reset up to and
                     including the episode's own.
``action_substeps``  per step, the physics substep (counted from the reset)
                     at which its action took effect, or, for an action that
                     never did, the substep at which the episode ended.
``ticks_elapsed``    per step, the control ticks it lasted.
``latency_ticks``    per step, ``info["latency_ticks"]`` (None: never applied).
``rewards``          per step, the reward (summed over its ticks).
``obs_digests``      the fingerprint of the reset's observation, then of each
                     step's (:func:`~remoteenv.latency.twin.digest.obs_digest`).
``terminated``, ``truncated``  how the episode ended.
``unreplayable``     None, or why the exact twin cannot replay it.
``link_delays``      with an emulated link, per step ``info["link_delay_s"]``
                     (wall seconds); null without one.

Plain trace files (:meth:`~remoteenv.latency.twin.LatencyRecorder.save_trace`)
are not recordings; :func:`~remoteenv.latency.twin.make_twin` still takes them
for the rounded lock-step twin.
"""

from __future__ import annotations

import json
import math
import os
import stat
from typing import Any

from remoteenv.latency.twin.episode import RecordedEpisode
from remoteenv.latency.twin.recorded_env import RecordedEnv
from remoteenv.wire.files.file_reads import UnreadableFile, parse_json, read_bytes, read_text
from remoteenv.wire.files.safe_writes import write_user_file
from remoteenv.wire.run_options.real_time_modes import MAX_REPLAY_STEPS, REAL_TIME_MODES

FORMAT = "remoteenv.real_time_recording"
VERSION = 2
#: The versions this reader reads.
READABLE_VERSIONS = (1, 2)
#: Largest recording file read (bytes).
MAX_RECORDING_BYTES = 64 * 1024 * 1024


def recording_document(episode: RecordedEpisode, env_id: str) -> dict[str, Any]:
    """``episode`` as the file's JSON object."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "env_id": env_id,
        "real_time_mode": episode.mode,
        "seed": episode.seed,
        "resets_after_seed": episode.resets_after_seed,
        "action_substeps": list(episode.action_substeps),
        "ticks_elapsed": list(episode.ticks_elapsed),
        "latency_ticks": list(episode.latency_ticks),
        "rewards": list(episode.rewards),
        "obs_digests": list(episode.obs_digests),
        "terminated": episode.terminated,
        "truncated": episode.truncated,
        "unreplayable": episode.unreplayable,
        "link_delays": None if episode.link_delays is None else list(episode.link_delays),
        "env": None if episode.env is None else episode.env.to_document(),
    }


def save_recording(episode: RecordedEpisode, path: str | os.PathLike[str], env_id: str) -> str:
    """Write ``episode`` to ``path`` (see the module docs); returns the path.
    An error names ``path`` (e.g. its folder does not exist)."""
    path = os.fspath(path)
    write_user_file(path, json.dumps(recording_document(episode, env_id)) + "\n", "recording")
    return path


def is_recording(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` holds a recording (a JSON object) rather than a plain trace.
    Raises :class:`~remoteenv.wire.files.file_reads.UnreadableFile` for a path that
    is no regular file (a FIFO is refused, never waited on)."""
    try:
        data = read_bytes(path, MAX_RECORDING_BYTES, what="recording or trace file")
    except UnreadableFile:
        if stat.S_ISREG(os.stat(path).st_mode):
            return False  # too large for a recording: a plain trace's reader decides
        raise  # a FIFO, device or directory is neither: said as such
    return data.lstrip().startswith(b"{")


def _ints(doc: dict[str, Any], key: str, n: int | None) -> list[int]:
    values = doc.get(key)
    if not isinstance(values, list) or (n is not None and len(values) != n):
        raise ValueError(f"recording field {key!r} must be a list of {n if n is not None else 'some'} ints")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values):
        raise ValueError(f"recording field {key!r} must hold ints >= 0")
    return values


def _as_float(value: Any) -> float | None:
    """``value`` as a float if it is a number (not a bool) a float holds, else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        return float(value)
    except OverflowError:  # an int beyond a double's range (10**400)
        return None


def _finite(value: Any) -> bool:
    number = _as_float(value)
    return number is not None and math.isfinite(number)


def episode_from_document(doc: Any, what: str = "recording") -> tuple[RecordedEpisode, str]:
    """A parsed recording: ``(episode, env_id)``; ValueError names what is wrong."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"{what} is not a remoteenv real-time recording (no 'format': {FORMAT!r})")
    if doc.get("version") not in READABLE_VERSIONS:
        raise ValueError(
            f"{what} has version {str(doc.get('version'))[:20]}; this remoteenv reads versions {READABLE_VERSIONS}"
        )
    mode = doc.get("real_time_mode")
    if mode not in REAL_TIME_MODES:
        raise ValueError(f"{what}: real_time_mode must be one of {REAL_TIME_MODES}")
    ticks = _ints(doc, "ticks_elapsed", None)
    n = len(ticks)
    if n > MAX_REPLAY_STEPS:
        raise ValueError(f"{what} has {n} steps, more than the {MAX_REPLAY_STEPS} a replay takes")
    latency = doc.get("latency_ticks")
    rewards = doc.get("rewards")
    digests = doc.get("obs_digests")
    if not (isinstance(latency, list) and isinstance(rewards, list) and len(latency) == len(rewards) == n):
        raise ValueError(f"{what}: latency_ticks and rewards need one value per step ({n})")
    if not all(v is None or _finite(v) for v in latency):
        raise ValueError(f"{what}: latency_ticks must be finite numbers or null")
    if not all(_as_float(v) is not None for v in rewards):
        raise ValueError(f"{what}: rewards must be numbers a float holds")
    if not isinstance(digests, list) or len(digests) != n + 1 or not all(isinstance(d, str) for d in digests):
        raise ValueError(f"{what}: obs_digests needs one string per step plus the reset's")
    seed, since = doc.get("seed"), doc.get("resets_after_seed")
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2**64):
        raise ValueError(f"{what}: seed must be an int in 0..2**64-1 (a reset's seed) or null")
    if not isinstance(since, int) or isinstance(since, bool) or since < 0:
        raise ValueError(f"{what}: resets_after_seed must be an int >= 0")
    unreplayable = doc.get("unreplayable")
    substeps = _ints(doc, "action_substeps", None if unreplayable else n)
    link = doc.get("link_delays")
    if link is not None:
        ok = isinstance(link, list) and len(link) == n
        if not ok or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < 3600 for v in link):
            raise ValueError(f"{what}: link_delays needs one delay per step ({n}), in seconds")
    env = None if doc.get("env") is None else RecordedEnv.from_document(doc["env"], what)
    episode = RecordedEpisode(
        seed,
        since,
        ticks_elapsed=ticks,
        latency_ticks=[None if v is None else float(v) for v in latency],
        rewards=[float(r) for r in rewards],  # checked above: each fits a float
        terminated=bool(doc.get("terminated")),
        truncated=bool(doc.get("truncated")),
        mode=mode,
        action_substeps=substeps,
        obs_digests=digests,
        unreplayable=None if unreplayable is None else str(unreplayable)[:500],
        link_delays=None if link is None else [float(v) for v in link],
        env=env,
    )
    return episode, str(doc.get("env_id") or "")[:200]


def load_recording(path: str | os.PathLike[str]) -> tuple[RecordedEpisode, str]:
    """Read a recording file: ``(episode, env_id)``."""
    what = f"recording {os.fspath(path)}"
    text = read_text(path, MAX_RECORDING_BYTES, what=what)
    return episode_from_document(parse_json(text, what=what), what)


__all__ = [
    "FORMAT",
    "MAX_RECORDING_BYTES",
    "READABLE_VERSIONS",
    "VERSION",
    "episode_from_document",
    "is_recording",
    "load_recording",
    "recording_document",
    "save_recording",
]
