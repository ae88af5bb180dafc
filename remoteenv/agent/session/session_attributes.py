"""The attributes both env classes read from their :class:`~remoteenv.agent.session.sim_session.SimSession`.

Runs in the agent process.
"""

from __future__ import annotations

from remoteenv.agent.launch.restart import RestartBudget
from remoteenv.agent.launch.sim_group import SimGroup
from remoteenv.agent.session.sim_session import SimSession
from remoteenv.wire.messages.handshake import Handshake


class SessionAttributes:
    """Mixin for an env that drives its sims through ``self._session``."""

    _session: SimSession

    @property
    def handshake(self) -> Handshake:
        """The (first) sim's handshake, renewed after a restart; ``hs["key"]`` reads the raw reply."""
        return self._session.handshake

    @property
    def restarts(self) -> RestartBudget:
        """The :class:`~remoteenv.agent.launch.restart.RestartBudget` (``.count`` restarts so far)."""
        return self._session.restarts

    @property
    def call_timeouts(self) -> dict[str, float | None]:
        """Per-command timeouts (seconds) overriding ``timeout``; may be edited."""
        return self._session.call_timeouts

    @property
    def launcher(self) -> SimGroup | None:
        """The group of the sims (None once closed)."""
        return None if self._session.closed else self._session.group
