"""A real-time run's reproducible twin: record its latencies, replay them in lock-step.

Runs in the agent process. In real time (``real_time=True``) the agent acts
once per *elastic* step: it gets an observation, thinks, sends an action,
and the physics runs on meanwhile with the previous action held. The twin
replays the same timing in lock-step, where it repeats exactly:

- :class:`LatencyRecorder` wraps a real-time env and turns every step's
  reply into the delays of the lock-step ticks it spanned. Each episode is
  saved as a plain :class:`remoteenv.delays.Trace` file (:meth:`LatencyRecorder.save`).
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
``ticks_elapsed = floor(L_j) + 1``. The twin gives the same decision the
lock-step latency ``m_j = ticks_elapsed - 1 = floor(L_j)``: the agent's
action is in force from the start of the tick in which real time applied it
mid-tick, and the decision is held for ``m_j + 1`` ticks, re-sent each tick
with the countdown delays ``m_j, m_j - 1, ..., 0``, all due at the same tick
(docs/latency.md: the newest of them is in force, the older copies are
dropped). So the trace of an episode is the concatenated countdowns, one
value per tick, and the hold lengths are read back from the values alone
(:func:`decision_ticks`). Reproduced exactly: which ticks each decision
spans, the observation the agent sees (the state at the end of the first
tick its action acted in), the reward summed over those ticks, and each
action's tick of effect. Not reproduced: within that tick, real time ran
the first ``frac(L_j)`` of it (``round(frac(L_j) * frame_skip)`` physics
substeps) on the previous action; the twin runs the whole tick on the new
one. A step whose action never took effect (the episode ended while the
agent thought) becomes the countdown ``ticks_elapsed, ..., 1``: due one tick
after the episode ended.
"""

from remoteenv.latency_twin.compare import (
    DEFAULT_RELATIVE_TOLERANCE,
    compare_real_time_and_replay,
    compare_recorded,
    compare_returns,
    replay_episode,
    run_real_time,
)
from remoteenv.latency_twin.recorder import LatencyRecorder, RecordedEpisode, save_episode
from remoteenv.latency_twin.replay import LockStepTwin, make_twin
from remoteenv.latency_twin.trace import ROUNDINGS, decision_ticks, twin_latency, twin_values

__all__ = [
    "DEFAULT_RELATIVE_TOLERANCE",
    "LatencyRecorder",
    "LockStepTwin",
    "ROUNDINGS",
    "RecordedEpisode",
    "compare_real_time_and_replay",
    "compare_recorded",
    "compare_returns",
    "decision_ticks",
    "make_twin",
    "replay_episode",
    "run_real_time",
    "save_episode",
    "twin_latency",
    "twin_values",
]
