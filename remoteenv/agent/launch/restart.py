"""Restart policy for ``restart_on_failure``: which failures a relaunch cures,
how many relaunches an env may spend, which instances a failure costs, how a
gather goes on around relaunches, and what the agent is told.

Runs in the agent process; used by the single and the vector env (through
:class:`remoteenv.agent.session.sim_session.SimSession`, which relaunches).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout, SimDiedError

#: Error kinds a fresh sim process can cure: the process died, or it is alive
#: but stopped answering. A scene exception or a bad action would only repeat.
RESTARTABLE_KINDS = frozenset({SimDiedError.KIND, RemoteEnvTimeout.KIND})

#: Keys of the ``info`` map of a step or reset that followed a restart.
INFO_RESTARTED = "remoteenv_restarted"
INFO_RESTARTS = "remoteenv_restarts"
INFO_ERROR = "remoteenv_error"


class RestartBudget:
    """Counts the relaunches of one env (all its instances together) against a cap.

    Args:
        enabled: ``restart_on_failure``; when False nothing is ever restarted.
        max_restarts: relaunches allowed over the env's lifetime; the failure
            after the last one is raised.
    """

    def __init__(self, enabled: bool, max_restarts: int) -> None:
        if max_restarts < 0:
            raise ValueError(f"max_restarts must be >= 0, got {max_restarts}")
        self.enabled = bool(enabled)
        self.max_restarts = int(max_restarts)
        self.count = 0

    def covers(self, err: RemoteEnvError) -> bool:
        """True if ``err`` is a failure a restart cures and restarts are on."""
        return self.enabled and err.kind in RESTARTABLE_KINDS

    def spend(self, err: RemoteEnvError) -> int:
        """Take one restart for ``err``; raise an error naming the cap if none is left.

        Returns the number of restarts spent so far, this one included."""
        if self.count >= self.max_restarts:
            raise type(err)(
                f"giving up after {self.count} restart(s) (max_restarts={self.max_restarts}); last failure: {err}",
                kind=err.kind,
                instance=err.instance,
            ) from err
        self.count += 1
        return self.count


def restarted_info(err: RemoteEnvError, restarts: int) -> dict[str, Any]:
    """The ``info`` entries that report a restart caused by ``err``."""
    return {INFO_RESTARTED: True, INFO_RESTARTS: restarts, INFO_ERROR: str(err)}


def instances_lost(err: RemoteEnvError, pending: Iterable[int]) -> list[int]:
    """The instances whose replies ``err`` cost, among those ``pending``: a
    timeout rebuilt every pending connection (their replies will never be
    read); a death costs only the instance that died."""
    if err.kind == RemoteEnvTimeout.KIND:
        return list(pending)
    return [] if err.instance is None else [err.instance]


def gather_restarting(
    gather: Callable[[dict[int, int], dict[int, dict[str, Any]]], object],
    relaunch: Callable[[int, RemoteEnvError], object],
    budget: RestartBudget,
    pending: dict[int, int],
    resend: Callable[[int], int] | None = None,
) -> tuple[dict[int, dict[str, Any]], dict[int, RemoteEnvError]]:
    """Wait for the replies of ``pending`` (``{instance: seq}``), relaunching
    each instance lost to a failure ``budget`` covers.

    ``gather(pending, replies)`` moves each reply into ``replies`` and its
    instance out of ``pending`` as it arrives, and raises on the first
    failure; ``relaunch(instance, err)`` brings a fresh sim up (spending the
    budget); ``resend(instance)`` sends the instance's request again to it and
    returns the new seq (without it the instance gets no reply). Returns the
    replies and ``{instance: error}`` of the instances relaunched. A failure
    the budget does not cover, or of an instance not pending, is raised.
    """
    replies: dict[int, dict[str, Any]] = {}
    failed: dict[int, RemoteEnvError] = {}
    while pending:
        try:
            gather(pending, replies)
        except RemoteEnvError as err:
            if not budget.covers(err) or err.instance not in pending:
                raise
            for p in instances_lost(err, pending):
                del pending[p]
                failed[p] = err
                relaunch(p, err)
                if resend is not None:
                    pending[p] = resend(p)
    return replies, failed
