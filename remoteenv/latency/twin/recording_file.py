"""The file of one recorded real-time episode, which the exact twin replays.

Runs in the agent process. A recording is a JSON object (written
atomically, never through a symlink; read through
:mod:`remoteenv.wire.files.file_reads` with a size bound, every field checked):

``format``           ``"remoteenv.real_time_recording"``.
``version``          1 (a reader refuses a version it does not know).
``env_id``           the env id the episode ran in.
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

Plain trace files (:meth:`~remoteenv.latency.twin.LatencyRecorder.save_trace`)
are not recordings; :func:`~remoteenv.latency.twin.make_twin` still takes them
for the rounded lock-step twin.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any

from remoteenv.latency.twin.episode import RecordedEpisode
from remoteenv.wire.files.file_reads import UnreadableFile, parse_json, read_bytes, read_text
from remoteenv.wire.files.safe_writes import write_atomic
from remoteenv.wire.run_options.real_time_modes import MAX_REPLAY_STEPS, REAL_TIME_MODES

FORMAT = "remoteenv.real_time_recording"
VERSION = 1
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
    }


def save_recording(episode: RecordedEpisode, path: str | os.PathLike[str], env_id: str) -> str:
    """Write ``episode`` to ``path`` (see the module docs); returns the path."""
    path = os.fspath(path)
    write_atomic(path, json.dumps(recording_document(episode, env_id)) + "\n", 0o644)
    return path


def is_recording(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` holds a recording (a JSON object) rather than a plain trace."""
    try:
        data = read_bytes(path, MAX_RECORDING_BYTES, what="recording or trace file")
    except UnreadableFile:
        return False
    return data.lstrip().startswith(b"{")


def _ints(doc: dict[str, Any], key: str, n: int | None) -> list[int]:
    values = doc.get(key)
    if not isinstance(values, list) or (n is not None and len(values) != n):
        raise ValueError(f"recording field {key!r} must be a list of {n if n is not None else 'some'} ints")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values):
        raise ValueError(f"recording field {key!r} must hold ints >= 0")
    return values


def episode_from_document(doc: Any, what: str = "recording") -> tuple[RecordedEpisode, str]:
    """A parsed recording: ``(episode, env_id)``; ValueError names what is wrong."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"{what} is not a remoteenv real-time recording (no 'format': {FORMAT!r})")
    if doc.get("version") != VERSION:
        raise ValueError(f"{what} has version {str(doc.get('version'))[:20]}; this remoteenv reads version {VERSION}")
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
    if not all(v is None or isinstance(v, (int, float)) and math.isfinite(v) for v in latency):
        raise ValueError(f"{what}: latency_ticks must be numbers or null")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in rewards):
        raise ValueError(f"{what}: rewards must be numbers")
    if not isinstance(digests, list) or len(digests) != n + 1 or not all(isinstance(d, str) for d in digests):
        raise ValueError(f"{what}: obs_digests needs one string per step plus the reset's")
    seed, since = doc.get("seed"), doc.get("resets_after_seed")
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)):
        raise ValueError(f"{what}: seed must be an int or null")
    if not isinstance(since, int) or isinstance(since, bool) or since < 0:
        raise ValueError(f"{what}: resets_after_seed must be an int >= 0")
    unreplayable = doc.get("unreplayable")
    substeps = _ints(doc, "action_substeps", None if unreplayable else n)
    episode = RecordedEpisode(
        seed,
        since,
        ticks_elapsed=ticks,
        latency_ticks=[None if v is None else float(v) for v in latency],
        rewards=[float(r) for r in rewards],
        terminated=bool(doc.get("terminated")),
        truncated=bool(doc.get("truncated")),
        mode=mode,
        action_substeps=substeps,
        obs_digests=digests,
        unreplayable=None if unreplayable is None else str(unreplayable)[:500],
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
    "VERSION",
    "episode_from_document",
    "is_recording",
    "load_recording",
    "recording_document",
    "save_recording",
]
