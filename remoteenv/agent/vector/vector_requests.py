"""The fan-out of a vector call: one request per sim process, replies gathered.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`). Process ``p``
hosts worlds ``slices[p]``. In lock-step with several worlds per process,
a vector step is one ``step_batch`` per process and a reset one
``reset_batch``; with one world per process (and always in real time, where
each process runs one paced clock) plain ``step``/``reset`` requests carry
less, and their replies are put in batch form here, so the caller sees one
shape; every reply is checked against the handshake first
(:attr:`~remoteenv.agent.session.sim_session.SimSession.checks`). A process lost to a failure the restart budget covers is relaunched
(:func:`remoteenv.agent.launch.restart.gather_restarting`): its worlds' episodes end
truncated at their last observation, and a reset is sent again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from remoteenv.agent.connection.fan_in import FanIn
from remoteenv.agent.connection.reply_checks import ReplyChecks
from remoteenv.agent.connection.shared_lane_client import SharedLanes
from remoteenv.agent.connection.take_over import retry_taking_over
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.restart import gather_restarting, restarted_info
from remoteenv.agent.session.sim_session import SimSession
from remoteenv.agent.vector.vector_results import ObsBatch, reset_reply_as_batch, step_reply_as_batch
from remoteenv.wire.protocol import OP_RESET, OP_STEP_AUTORESET, OP_STEP_RESET


class VectorRequests:
    """Sends the requests of vector calls and gathers the replies, in batch form.

    Args:
        session: the sims and their connections (``session.conns[p]``).
        slices: ``(first, end)`` world indices of each process.
        real_time: the sims run paced clocks (one world each; plain requests only).
        same_step: the autoreset mode is ``SAME_STEP`` (a relaunched process's
            worlds start their new episodes within the failed step).
    """

    def __init__(
        self, session: SimSession, slices: Sequence[tuple[int, int]], *, real_time: bool, same_step: bool
    ) -> None:
        self.session = session
        self.slices = list(slices)
        self.real_time = real_time
        #: One world per process: plain requests carry less than the batch ones.
        self.plain_steps = real_time or all(hi - lo == 1 for lo, hi in self.slices)
        self.same_step = same_step
        self.fan_in = FanIn()
        #: Shared-memory regions of the local sims (batched steps).
        self.lanes = SharedLanes(session.handshake.observation_space, session.checks)

    def gather(
        self, pending: dict[int, int], cmd: str, resend: Callable[[int], int] | None = None
    ) -> tuple[dict[int, dict[str, Any]], dict[int, RemoteEnvError]]:
        """Replies to ``pending`` (``{process: seq}`` of ``cmd`` requests),
        relaunching processes lost to a covered failure; see
        :func:`~remoteenv.agent.launch.restart.gather_restarting`."""
        session, fan_in, what = self.session, self.fan_in, f"'{cmd}'"
        timeout = session.timeout_for(cmd)

        def gather_some(waiting: dict[int, int], replies: dict[int, dict[str, Any]]) -> None:
            fan_in.gather(session.conns, waiting, what, timeout, replies)

        def relaunch(p: int, err: RemoteEnvError) -> None:
            fan_in.forget()
            session.relaunch(p, err)

        return gather_restarting(gather_some, relaunch, session.restarts, pending, resend)

    # ------------------------------------------------------------ reset

    def reset(
        self, worlds_of: dict[int, list[int]], seeds: Sequence[int | None], options: dict[str, Any] | None
    ) -> tuple[dict[int, dict[str, Any]], dict[int, RemoteEnvError]]:
        """Reset worlds ``worlds_of[p]`` (indices within process ``p``) with
        ``seeds`` (one per world of the vector). Returns each process's reply in
        ``reset_batch`` form and ``{process: error}`` of those relaunched."""
        conns = self.session.conns

        def send_reset(p: int) -> int:
            lo, worlds = self.slices[p][0], worlds_of[p]
            if self.real_time:
                return conns[p].send("reset", seed=seeds[lo], options=options)
            return conns[p].send("reset_batch", worlds=worlds, seeds=[seeds[lo + w] for w in worlds], options=options)

        def reset_all() -> tuple[dict[int, dict[str, Any]], dict[int, RemoteEnvError]]:
            return self.gather({p: send_reset(p) for p in worlds_of}, "reset", resend=send_reset)

        # A world may be refused a moment after its previous driver closed: all are reset again.
        replies, restarted = retry_taking_over(reset_all)
        checks = self._checks()
        for p, r in replies.items():
            if self.real_time:
                replies[p] = reset_reply_as_batch(checks.reset(conns[p], r))
            else:
                checks.batch(conns[p], "reset_batch", r, len(worlds_of[p]))
        return replies, restarted

    # ------------------------------------------------------------ step

    def step(self, ops: np.ndarray, actions: Any, last_obs: Any, obs_batch: ObsBatch) -> dict[int, dict[str, Any]]:
        """Step (or reset, per ``ops``) every world with ``actions``; returns each
        process's result in ``step_batch`` form. ``last_obs`` is the batch the
        previous call returned (for the worlds of a relaunched process)."""
        return self.finish_step(self.start_step(ops, actions), ops, actions, last_obs, obs_batch)

    def start_step(self, ops: np.ndarray, actions: Any, think_s: float = 0.0) -> dict[int, int]:
        """Send the requests of a vector step (see :meth:`step`); returns ``{process: seq}``.
        ``think_s``: seconds since the previous vector step returned to the
        caller (0: not told), told to sims reached through their region."""
        conns = self.session.conns
        if self.plain_steps:
            pending = {}
            for p, (lo, _) in enumerate(self.slices):
                if ops[lo] == OP_RESET:
                    pending[p] = conns[p].send("reset", seed=None, options=None)
                else:
                    pending[p] = conns[p].send("step", action=actions[lo])
            return pending
        pending = {}
        handshakes, lanes = self.session.handshakes, self.lanes
        ops_list: list[int] | None = None
        whole = len(self.slices) == 1  # one process of every world: its blocks are the arrays themselves
        for p, (lo, hi) in enumerate(self.slices):
            acts = actions if whole else actions[lo:hi]
            offered = handshakes[p].offers("shared_batch")
            seq = lanes.post(p, conns[p], offered, ops if whole else ops[lo:hi], acts, think_s=think_s)
            if seq is not None:
                pending[p] = seq
                continue
            if ops_list is None:
                ops_list = ops.tolist()
            if lanes.put_actions(p, conns[p], offered, acts):
                pending[p] = conns[p].send("step_batch", ops=ops_list[lo:hi], shared=True)
            else:
                pending[p] = conns[p].send("step_batch", ops=ops_list[lo:hi], actions=acts)
        return pending

    def finish_step(
        self, pending: dict[int, int], ops: np.ndarray, actions: Any, last_obs: Any, obs_batch: ObsBatch
    ) -> dict[int, Any]:
        """Gather the replies of a vector step :meth:`start_step` sent (see :meth:`step`)."""
        if self.plain_steps:
            return self._finish_single_worlds(pending, ops, last_obs, obs_batch)
        sent = dict(pending)
        results: dict[int, Any] = {}
        conns, checks, lanes = self.session.conns, self._checks(), self.lanes
        try:
            replies, failed = self.gather(pending, "step_batch")
            for p, reply in replies.items():
                lo, hi = self.slices[p]
                if reply.get("region") is not True:  # a region reply's numbers have the layouts checked before
                    lanes.vouch(p, sent[p], reply)  # a reply marked shared answers a request that used the region
                    checks.batch(conns[p], "step_batch", reply, hi - lo, shared=reply.get("shared") is True)
                # Vouched for again there (a region reply: first); a shared reply's arrays come from the
                # region; an announcement of its info columns is checked there.
                results[p] = lanes.take(p, conns[p], sent[p], reply, hi - lo)
        except BaseException:
            for p in sent:  # abandoned: their replies will not be read
                lanes.forget(p)
            raise
        for p, err in failed.items():
            lanes.forget(p)
            results[p] = self._restarted_results(p, err, last_obs, obs_batch)
        return results

    def _finish_single_worlds(
        self, pending: dict[int, int], ops: np.ndarray, last_obs: Any, obs_batch: ObsBatch
    ) -> dict[int, dict[str, Any]]:
        """One world per process: gather the plain ``step``/``reset`` replies, then
        send a ``reset`` to each world whose op asks for one after its step."""
        conns, checks = self.session.conns, self._checks()
        replies, failed = self.gather(pending, "step")
        results = {p: self._restarted_results(p, e, last_obs, obs_batch) for p, e in failed.items()}
        resets: dict[int, int] = {}
        for p, r in replies.items():
            op = ops[self.slices[p][0]]
            if op == OP_RESET:
                results[p] = reset_reply_as_batch(checks.reset(conns[p], r), as_step=True)
                continue
            results[p] = step_reply_as_batch(checks.step(conns[p], r))
            if op == OP_STEP_RESET or (op == OP_STEP_AUTORESET and (r["terminated"] or r["truncated"])):
                resets[p] = conns[p].send("reset", seed=None, options=None)
        reset_replies: dict[int, dict[str, Any]] = {}
        if resets:
            self.fan_in.gather(conns, resets, "'reset'", self.session.timeout_for("reset"), reset_replies)
        for p, r in reset_replies.items():
            checks.reset(conns[p], r)
            res = results[p]
            res["final"] = [[0, res["obs"][0], res["info"]["maps"][0]]]
            res["obs"] = [r["obs"]]
            res["info"] = {"maps": [r["info"]]}
        return results

    def _checks(self) -> ReplyChecks:
        checks = self.session.checks
        assert checks is not None, "the session is open"
        return checks

    def _restarted_results(self, p: int, err: RemoteEnvError, last_obs: Any, obs_batch: ObsBatch) -> dict[str, Any]:
        """``step_batch``-form results for the worlds of relaunched process ``p``:
        truncated at their last observation, reward 0, the restart in their info
        (with ``SAME_STEP``: new episodes already started, the ended ones final)."""
        lo, hi = self.slices[p]
        k = hi - lo
        info = restarted_info(err, self.session.restarts.count)
        last = obs_batch.rows(last_obs, lo, hi)
        result: dict[str, Any] = {
            "obs": last,
            "reward": [0.0] * k,
            "terminated": [False] * k,
            "truncated": [True] * k,
            "info": {"maps": [dict(info) for _ in range(k)]},
            "final": [],
        }
        if self.same_step:
            if self.real_time:
                fresh = [self.session.request(p, "reset", seed=None, options=None)["obs"]]
            else:
                fresh = self.session.request(p, "reset_batch", worlds=list(range(k)), seeds=[None] * k, options=None)[
                    "obs"
                ]
            result["obs"] = fresh
            result["final"] = [[w, last[w], dict(info)] for w in range(k)]
        return result


__all__ = ["VectorRequests"]
