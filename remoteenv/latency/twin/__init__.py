"""A real-time run's exact twin: record it, save it, replay it bit for bit.

Runs in the agent process. Physics is deterministic, so a real-time episode
is fully determined by its reset, its actions and the physics substep at
which each action took effect (``info["action_substep"]``):

- :class:`LatencyRecorder` wraps a real-time env and keeps, per step, that
  substep, the ticks the step lasted, its reward and a fingerprint of its
  observation (:mod:`~remoteenv.latency.twin.digest`); whatever cannot be
  replayed (a restart, a step that raised, a reset with options) is named
  in the episode. :meth:`LatencyRecorder.save` writes one episode as a
  versioned JSON recording (:mod:`~remoteenv.latency.twin.recording_file`).
  :class:`LatencyRecorderVector` does the same per world of a real-time
  :class:`remoteenv.RemoteVectorEnv`.
- :func:`make_twin` on a recording (or a :class:`RecordedEpisode`) returns
  an :class:`ExactTwin`: a real-time env of the recording's regime whose
  sim replays the schedule without its clock, each action applied at its
  recorded substep by the same code that ran in real time
  (:mod:`remoteenv.sim.stepping.real_time_replay`).
- :func:`compare_real_time_and_replay` runs a policy in real time, replays
  every episode and reports each as identical or with its first differing
  step (:func:`first_difference`).

The older rounded twin remains: :meth:`LatencyRecorder.save_trace` writes a
plain :class:`remoteenv.delays.Trace` of the latencies rounded to whole
ticks (:func:`twin_values`), and :func:`make_twin` on such a trace returns
a :class:`LockStepTwin` that replays it in lock-step with
``action_delay=Trace(...)``: the same ticks per step, but actions switched
at tick boundaries instead of substeps, so not the same run.
``docs/latency-twin.md`` has both, the file format and the measurements.
"""

from remoteenv.latency.twin.compare import (
    compare_real_time_and_replay,
    compare_recorded,
    first_difference,
    replay_episode,
    run_real_time,
)
from remoteenv.latency.twin.exact_twin import ExactTwin
from remoteenv.latency.twin.recorder import LatencyRecorder, RecordedEpisode, save_episode
from remoteenv.latency.twin.recording_file import load_recording, save_recording
from remoteenv.latency.twin.replay import LockStepTwin, make_twin
from remoteenv.latency.twin.return_stats import DEFAULT_RELATIVE_TOLERANCE, compare_returns
from remoteenv.latency.twin.trace import ROUNDINGS, decision_ticks, twin_latency, twin_values
from remoteenv.latency.twin.vector_recorder import LatencyRecorderVector

__all__ = [
    "DEFAULT_RELATIVE_TOLERANCE",
    "ExactTwin",
    "LatencyRecorder",
    "LatencyRecorderVector",
    "LockStepTwin",
    "ROUNDINGS",
    "RecordedEpisode",
    "compare_real_time_and_replay",
    "compare_recorded",
    "compare_returns",
    "decision_ticks",
    "first_difference",
    "load_recording",
    "make_twin",
    "replay_episode",
    "run_real_time",
    "save_episode",
    "save_recording",
    "twin_latency",
    "twin_values",
]
