"""Torch's threads for the learner's update: all of them where the update runs, fewer while the sims step.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`, through
:class:`~remoteenv.agent.vector.torch_threads.TorchThreads`). ``torch_threads="auto"``
lowers torch's thread count to the CPUs a vector env's local sims leave,
since torch's idle threads would spin through every vector step. But a
training loop's update (a PPO-shaped loop's epochs of SGD) runs between two
vector steps while the sims wait for the next request, and there torch's
threads have the CPUs to themselves.

:class:`UpdateThreads` predicts the update: a rollout ends with a *long
think* (the caller away for :data:`LONG_THINK_S` or more between two steps),
and when the last two rollouts had the same number of steps, the think after
that many steps is taken for the update. For it, torch gets its threads back
(``high``) and every local sim is told to stop waiting hot (the doorbell's
``AGENT_AWAY``), so the update has every CPU. When the next step starts,
torch goes back to ``low`` threads and the idle ones stop spinning at once
(OpenMP's ``omp_pause_resource_all``, which frees the calling thread's pool;
the next update starts its threads again).

Whether this pays depends on the learner (a small network's update may run
no faster on two threads), so the updates are timed both ways: two of each
first, then the faster way (two threads must be at least
:data:`MARGIN` faster), trying the other way again every
:data:`RETRY_EVERY` updates. Nothing is raised while the process's hot waits cool down
after a stall (a busy neighbour holds the CPUs). A user who changes torch's
thread count meanwhile ends it for good. Measured gain: docs/performance.md ("Torch's
threads for the update").
"""

from __future__ import annotations

import ctypes
import os
import statistics
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from remoteenv.wire.shared_memory.hot_wait import neighbours_busy

#: A think at least this long (seconds) between two vector steps ends a rollout.
LONG_THINK_S = 2e-3
#: Updates timed each way before choosing; the last this many of each are kept.
TRIALS = 2
KEPT = 4
#: Two threads are chosen only if their updates take at most this share of one thread's.
MARGIN = 0.97
#: Every this many predicted updates the way not chosen is timed once more.
RETRY_EVERY = 32
#: Shared objects whose ``omp_pause_resource_all`` ends an OpenMP pool's spin.
_OPENMP_LIBRARIES = ("libgomp", "libiomp5", "libomp")


def openmp_pause(torch_dir: str | None = None) -> Callable[[], Any] | None:
    """``omp_pause_resource_all(omp_pause_soft)`` of the OpenMP runtime loaded in
    this process (the one torch's threads use: under ``torch_dir``, torch's
    package directory, if one is there), or None if none is loaded or it
    lacks the call (then :class:`UpdateThreads` is not used)."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            paths = {line.split()[-1] for line in maps if "/lib" in line and ".so" in line}
    except OSError:
        return None
    inside = (torch_dir.rstrip(os.sep) + os.sep) if torch_dir else None
    for path in sorted(paths, key=lambda p: (not (inside and p.startswith(inside)), p)):
        if os.path.basename(path).startswith(_OPENMP_LIBRARIES):
            try:
                pause = ctypes.CDLL(path).omp_pause_resource_all
            except (OSError, AttributeError):
                continue
            pause.argtypes = [ctypes.c_int]
            pause.restype = ctypes.c_int
            return lambda: pause(1)  # omp_pause_soft
    return None


class _Timings:
    """The predicted updates' lengths (seconds), with one thread count and the other."""

    def __init__(self) -> None:
        self.low: deque[float] = deque(maxlen=KEPT)
        self.high: deque[float] = deque(maxlen=KEPT)
        self.predicted = 0

    def choose(self) -> bool:
        """Whether the next predicted update runs on ``high`` threads."""
        self.predicted += 1
        if len(self.low) < TRIALS or len(self.high) < TRIALS:
            return len(self.high) < len(self.low)  # one thread first, then taking turns
        high_wins = statistics.median(self.high) <= MARGIN * statistics.median(self.low)
        if self.predicted % RETRY_EVERY == 0:
            return not high_wins
        return high_wins

    def add(self, high: bool, seconds: float) -> None:
        (self.high if high else self.low).append(seconds)


class UpdateThreads:
    """Torch at ``high`` threads for the predicted update, ``low`` otherwise.

    Args:
        torch: the torch module.
        low: threads while the sims step (what ``"auto"`` set).
        high: threads for the update (torch's count before ``"auto"`` lowered it).
        pause: ends the idle threads' spin (:func:`openmp_pause`).
        away: tells the local sims that the caller's update has begun.
        clock: seconds, monotonic (tests pass their own).
        busy: whether something else holds this process's CPUs now (the hot
            waits cool down after a stall); then nothing is raised.
    """

    def __init__(
        self,
        torch: Any,
        low: int,
        high: int,
        pause: Callable[[], Any],
        away: Callable[[], None],
        clock: Callable[[], float] = time.perf_counter,
        busy: Callable[[], bool] = neighbours_busy,
    ) -> None:
        self._torch, self.low, self.high = torch, low, high
        self._pause, self._away, self._clock, self._busy = pause, away, clock, busy
        self.timings = _Timings()
        #: Vector steps since the last long think; the last two rollouts' lengths.
        self._steps = 0
        self._lengths: deque[int] = deque(maxlen=2)
        self._returned_at: float | None = None
        #: The think going on now was predicted as an update (None: not), raised or not.
        self._predicted: bool | None = None
        #: Whether torch runs on ``high`` threads now.
        self.raised = False
        #: False once the user changed torch's threads (then this leaves them alone).
        self.active = True

    def step_returns(self) -> None:
        """A vector step returns to the caller now: if the update is due, raise."""
        self._steps += 1
        self._returned_at = self._clock()
        if not self.active or len(self._lengths) < 2 or self._lengths[0] != self._lengths[1]:
            return
        if self._steps != self._lengths[1]:
            return
        if self._torch.get_num_threads() != self.low:
            self.active = False  # the user set another count: theirs from now on
            return
        if self._busy():
            return  # a busy neighbour would take the second thread's CPU: neither raised nor timed
        high = self.timings.choose()
        self._predicted = high
        if high:
            self._torch.set_num_threads(self.high)
            self.raised = True
            self._away()

    def step_starts(self) -> None:
        """A vector step starts now: lower torch's threads if raised, time the
        think if it was a predicted update, and count the rollout."""
        now = self._clock()
        think = None if self._returned_at is None else now - self._returned_at
        self._returned_at = None
        self._lower()
        predicted, self._predicted = self._predicted, None
        if think is None or think < LONG_THINK_S:
            return
        if predicted is not None:
            self.timings.add(predicted, think)
        self._lengths.append(self._steps)
        self._steps = 0

    def interrupted(self) -> None:
        """A reset or close: lower torch's threads if raised, and forget the think."""
        self._returned_at = None
        self._predicted = None
        self._lower()

    def _lower(self) -> None:
        if not self.raised:
            return
        self.raised = False
        if self._torch.get_num_threads() != self.high:
            self.active = False  # the user set another count during the update: leave it
            return
        self._torch.set_num_threads(self.low)
        self._pause()


__all__ = ["LONG_THINK_S", "UpdateThreads", "openmp_pause"]
