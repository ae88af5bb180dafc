"""A request posted in the region that is a plain step of every world, served from the sim's wait.

Runs in the sim process (lock step). Most requests a vector env posts in its
sim process's region (:mod:`remoteenv.wire.shared_memory.doorbell`) are
plain: every world of the process steps, none resets, none is named. The
server's wait finds such a request in the region
(:meth:`~remoteenv.sim.serving.waits.ServingWaits.for_requests`) and hands
it to :class:`PlainRegionStep` without the command table's dispatch:
:meth:`PlainRegionStep.take` recognises it straight from the region's blocks
and takes it, with the checks :meth:`BatchCommands.from_region
<remoteenv.sim.stepping.batch_commands.BatchCommands.from_region>` makes
(a header untampered with, every world reset before, the actions checked),
and :meth:`PlainRegionStep.step` steps the worlds and answers as that method
would, with the same reply. Any other request is left as it is, untaken, for
the usual way, which serves it or says what is wrong with it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.stepping.batch_step import WorldsStepper
from remoteenv.sim.transport.channels import Channel
from remoteenv.sim.transport.shared_lane_server import SharedLane
from remoteenv.wire.messages.batch_encoding import columnar_infos, stack


class PlainRegionStep:
    """Plain steps of every world of ``stepper`` posted in ``lane``'s region.

    Args:
        lane: the process's region.
        stepper: steps the process's worlds together.
        check: the action check of a request's actions (``check(actions, n)``).
        all_reset: whether every world has been reset once (before that, a step
            goes the usual way, which refuses the worlds not reset yet).
    """

    def __init__(
        self, lane: SharedLane, stepper: WorldsStepper, check: Callable[[Any, int], Any], all_reset: Callable[[], bool]
    ) -> None:
        self._lane, self._stepper, self._check, self._all_reset = lane, stepper, check, all_reset
        self._worlds = list(range(len(stepper.envs)))

    def take(self, seq: int, channel: Channel | None) -> np.ndarray | None:
        """Take request ``seq`` if it is a plain step of every world: its checked
        actions; None, with nothing taken, otherwise (see
        :meth:`~remoteenv.sim.transport.lane_requests.LaneRequests.take_plain`)."""
        if not self._all_reset():
            return None
        return self._lane.take_plain(seq, channel, self._check)

    def step(self, actions: np.ndarray, seq: int) -> dict[str, Any] | None:
        """Step every world with ``actions`` (taken by :meth:`take` for request
        ``seq``) and answer in the region where it fits: the reply
        :meth:`~remoteenv.sim.stepping.batch_commands.BatchCommands.from_region`
        gives (None: answered in the region, the agent watches). Raises as it does."""
        lane, n = self._lane, len(self._worlds)
        batch = self._stepper.step(self._worlds, actions, lane.obs_rows(n), lambda: lane.physics_done(seq))
        return region_reply(lane, seq, batch)


def region_reply(lane: SharedLane, seq: int, batch: BatchResult) -> dict[str, Any] | None:
    """The reply to region request ``seq``, a plain step whose results are
    ``batch``: answered in ``lane``'s region where it fits (None, or
    ``{"region": true}`` to wake the agent), else its fields for the pipe (with
    a new info layout where the region can hold the infos next time)."""
    done, reply = lane.answer(seq, batch)
    if done:
        return reply
    if reply is not None:
        reply["info"] = batch_infos(batch)
        return reply
    return plain_step_reply(batch)


def batch_infos(batch: BatchResult) -> dict[str, Any]:
    """The infos of a batch in their wire form (see :func:`columnar_infos`)."""
    info = batch.wire_columns()
    if info is None:
        info = columnar_infos([batch.world_info(j) for j in range(len(batch.reward))])
    return info


def plain_step_reply(batch: BatchResult) -> dict[str, Any]:
    """The reply of a ``step_batch`` that stepped every world and reset none."""
    return {
        "obs": batch.obs if isinstance(batch.obs, np.ndarray) else stack(batch.obs),
        "reward": batch.reward.tolist(),
        "terminated": batch.terminated.tolist(),
        "truncated": [False] * len(batch.reward),
        "info": batch_infos(batch),
        "final": [],
    }


__all__ = ["PlainRegionStep", "batch_infos", "plain_step_reply", "region_reply"]
