"""The vector step of one sim process's worlds through its region, with no look-up on the way.

Runs in the agent process (:class:`~remoteenv.agent.vector.vector_episodes.VectorEpisodes`).
The default layout on a small machine runs every world in one sim process
(:func:`~remoteenv.agent.vector.vector_layout.default_envs_per_process`), and
most of its vector steps are plain: every world steps, none resets. Once one
such step went the usual way (:class:`~remoteenv.agent.vector.vector_requests.VectorRequests`:
its region attached, its request blocks and reply views made, its info
layout learned), :class:`LeanStep` posts the next ones in the region
(:class:`~remoteenv.agent.connection.shared_lane_client.LaneReady`) and
waits for their replies there
(:meth:`~remoteenv.agent.connection.region_watch.RegionWatch.wait_region`),
with the same checks: the actions checked before (by the caller), the
region's header checked for tampering before each request, the reply taken
only for its own request and in the info layout announced. Anything else (a
reset in the step, actions of another form, a frame on the pipe, a sim
gone, a header tampered with) goes the usual way from where it stands, with
the same results.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from remoteenv.agent.connection.shared_lane_client import LaneReady, SharedLanes
from remoteenv.agent.session.sim_session import SimSession
from remoteenv.agent.vector.vector_results import from_one_region
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory.doorbell import REP_INFO


class LeanStep:
    """Plain vector steps of the ``n`` worlds of ``session``'s only sim
    process through its region (see the module docstring).

    Args:
        session: the open session (one sim process).
        lanes: the vector env's regions (:attr:`VectorRequests.lanes`).
        n: the number of worlds.
        obs_dtype: the observation space's dtype (a Box).
    """

    def __init__(self, session: SimSession, lanes: SharedLanes, n: int, obs_dtype: Any) -> None:
        self._session, self._lanes, self._n, self._obs_dtype = session, lanes, n, obs_dtype
        self._ready: LaneReady | None = None

    def post(self, ops: np.ndarray, actions: Any, think_s: float) -> int | None:
        """Post a step of ``ops`` (planned: the read-only plan of a plain step)
        with ``actions`` (checked) in the region; its ``seq``, or None (nothing
        sent: send it the usual way)."""
        conn = self._session.conns[0]
        ready = self._ready
        if (
            ready is None
            or ready.generation != self._lanes.generation
            or ready.conn is not conn
            or ops is not ready.ops
        ):
            ready = self._ready = self._lanes.ready(0, conn, self._n, ops)
            if ready is None:
                return None
        block = ready.actions
        if type(actions) is not np.ndarray or actions.dtype != block.dtype or actions.shape != block.shape:
            return None
        if 0 in ready.pending or ready.bell.agent_tampered() is not None:
            return None  # the usual way finds out which, and says so
        block[...] = actions
        seq: int = ready.conn.post(ready.bell, self._n, False, think_s, True)  # type: ignore[attr-defined]
        ready.pending[0] = seq
        return seq

    def finish(self, seq: int) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]] | None:
        """The results of step ``seq`` that :meth:`post` sent, once its reply is
        in the region: ``(obs, rewards, terminated, truncated, infos)`` in fresh
        arrays, the time limit not yet applied; None when anything else came
        first (then gather it the usual way: the request is still pending)."""
        ready = self._ready
        assert ready is not None, "a step was posted"
        try:
            if not ready.conn.wait_region(seq):  # type: ignore[attr-defined]
                return None
            view = ready.view
            if ready.bell.word(REP_INFO) != view.version:  # the usual way refuses it, and says why
                self._lanes.take(0, ready.conn, seq, protocol.region_reply(seq), self._n)
            del ready.pending[0]
            return from_one_region(view, self._n, self._obs_dtype)
        except BaseException:
            self._lanes.forget(0)
            raise


__all__ = ["LeanStep"]
