"""A real-time run's reproducible twin: record its latencies, replay them in lock-step.

Runs in the agent process. In real time (``real_time=True``) the agent acts
once per *elastic* step: it gets an observation, thinks, sends an action,
and the physics runs on meanwhile with the previous action held. The twin
replays the same timing in lock-step, where it repeats exactly:

- :class:`LatencyRecorder` wraps a real-time env and turns every step's
  reply into the delays of the lock-step ticks it spanned. Each episode is
  saved as a plain :class:`remoteenv.delays.Trace` file (:meth:`LatencyRecorder.save`).
  :class:`LatencyRecorderVector` does the same per world of a real-time
  :class:`remoteenv.RemoteVectorEnv`.
- :func:`make_twin` launches the lock-step env with ``action_delay=Trace(...)``
  of one recorded episode and wraps it in :class:`LockStepTwin`, whose
  ``step`` is one elastic step: it holds the agent's decision for the ticks
  the real-time step took.
- :func:`compare_real_time_and_replay` runs a policy both ways and compares
  the return distributions (:func:`compare_returns`).

The mapping (``docs/latency-twin.md`` has it with a worked example). A
real-time step ``j`` whose action took effect ``L_j`` control ticks after the
observation it was computed from (``info["latency_ticks"]``, fractional:
sim time from that observation to the physics substep where the action took
effect) is answered at the end of that tick, so its reply reports
``ticks_elapsed = floor(L_j) + 1``. The twin holds the same decision for
those ``ticks_elapsed`` lock-step ticks, re-sending it each tick with the
countdown delays ``L'_j, L'_j - 1, ...``, so that every copy is due at the
same tick (docs/delays.md: the newest due copy is in force, older ones are
dropped) and the action starts at a whole tick ``L'_j`` after the
observation. ``L'_j`` is ``L_j`` rounded to the nearest tick (default) or
down (``rounding="floor"``; see :func:`twin_latency`). The trace of an
episode is its countdowns, one value per tick, and the hold lengths are read
back from the values alone (:func:`decision_ticks`).

Reproduced exactly: the ticks each decision spans and so the sim time of
every observation the agent sees, the reward summed over those ticks, and
the tick each action's effect starts at, to within half a tick of real
time. Not reproduced: real time switched actions at a physics substep
inside a tick; the twin switches at the nearest tick boundary (so with
``"nearest"`` an action real time applied in the second half of the last
tick of its step starts in the next tick, after the reply, and one that is
then overtaken by the next action never acts, as it barely did). A step
whose action never took effect (the episode ended while the agent thought)
gets ``L' = ticks_elapsed``: due one tick after the end.
"""

from remoteenv.latency_twin.compare import (
    compare_real_time_and_replay,
    compare_recorded,
    first_difference,
    replay_episode,
    run_real_time,
)
from remoteenv.latency_twin.exact_twin import ExactTwin
from remoteenv.latency_twin.recorder import LatencyRecorder, RecordedEpisode, save_episode
from remoteenv.latency_twin.recording_file import load_recording, save_recording
from remoteenv.latency_twin.replay import LockStepTwin, make_twin
from remoteenv.latency_twin.return_stats import DEFAULT_RELATIVE_TOLERANCE, compare_returns
from remoteenv.latency_twin.trace import ROUNDINGS, decision_ticks, twin_latency, twin_values
from remoteenv.latency_twin.vector_recorder import LatencyRecorderVector

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
