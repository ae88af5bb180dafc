"""Pausing the clocks of real-time sims while the agent does something else.

Runs in the agent process. A learner that updates between rollouts pauses
the world so it does not run uncontrolled meanwhile: every sim of the env
gets ``pause`` (all requests in flight at once, then every reply awaited),
physics stops with the held action kept, and ``resume`` shifts every
deadline by the paused wall time (see :mod:`remoteenv.sim.stepping.real_time`), so
the pause counts in no latency statistic. In lock-step nothing runs between
steps anyway: both are no-ops there and send nothing.

Call them between steps (no ``step`` in flight): a step sent to a paused
sim is answered only after the resume.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import Any

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.session.sim_session import SimSession


class Pauser:
    """Pause and resume every sim of one session.

    Attributes:
        paused: whether the sims are paused now (always False in lock-step).
        paused_s: total wall seconds the sims stood paused, as they measured it.
        pauses: completed pause/resume pairs.
    """

    def __init__(self, session: SimSession) -> None:
        self._session = session
        self.paused = False
        self.paused_s = 0.0
        self.pauses = 0

    @property
    def applies(self) -> bool:
        """True when the sims run on a clock (real time); pausing lock-step does nothing."""
        return self._session.handshake.real_time

    def _all(self, cmd: str) -> list[dict[str, Any]]:
        session = self._session
        hs = session.handshake
        if not hs.offers(cmd):
            raise RemoteEnvError(
                f"{session.label}: the sim does not answer {cmd!r} (its commands: "
                f"{sorted(hs.commands or [])}); it cannot be paused",
                kind="protocol",
            )
        conns = [session.connection(i, cmd) for i in range(max(1, len(session.conns)))]
        timeout = session.timeout_for(cmd)
        seqs = [conn.send(cmd) for conn in conns]
        replies = [conn.receive(seq, timeout, what=repr(cmd)) for conn, seq in zip(conns, seqs)]
        if session.checks is not None:
            for i, (conn, reply) in enumerate(zip(conns, replies)):
                session.checks.sim_times(conn, cmd, reply, session.handshakes[i].num_worlds)
        return replies

    def pause(self) -> list[float]:
        """Stop every sim's clock; returns each world's sim time (s) at the pause
        (empty in lock-step). Pausing a paused env does nothing more."""
        if not self.applies:
            return []
        replies = self._all("pause")
        self.paused = True
        return [float(t) for reply in replies for t in reply["sim_time"]]

    def resume(self) -> float:
        """Restart the clocks where they stopped; returns the longest pause (wall
        seconds) a sim measured (0.0 if none was paused, and in lock-step)."""
        if not self.applies:
            return 0.0
        replies = self._all("resume")
        was_paused = self.paused
        self.paused = False
        paused = max((float(reply.get("paused_s", 0.0)) for reply in replies), default=0.0)
        if was_paused:
            self.paused_s += paused
            self.pauses += 1
        return paused

    @contextmanager
    def held(self) -> Iterator[None]:
        """Paused for the ``with`` block; resumed on the way out (also on an error)."""
        self.pause()
        try:
            yield
        finally:
            self.resume()


class Pausable:
    """``pause()``, ``resume()`` and ``paused()`` for an env class holding a
    :class:`Pauser` as ``_pauser`` (both env classes mix this in)."""

    _pauser: Pauser

    def pause(self) -> list[float]:
        """Real time: stop the sims' clocks between steps (physics stops, the held
        action is kept); nothing runs until :meth:`resume`. Returns every world's
        sim time (s) at the pause. A no-op in lock-step (returns [])."""
        return self._pauser.pause()

    def resume(self) -> float:
        """Restart the clocks where they stopped, every deadline shifted so the
        pause counts in no latency figure; returns the paused wall seconds
        (0.0 in lock-step)."""
        return self._pauser.resume()

    def paused(self) -> AbstractContextManager[None]:
        """``with env.unwrapped.paused(): learner.update()``: paused for the block."""
        return self._pauser.held()

    @property
    def pausing(self) -> Pauser:
        """The :class:`Pauser`: ``pauses`` so far and ``paused_s`` in total."""
        return self._pauser

    @property
    def is_paused(self) -> bool:
        """Whether the sims are paused now (always False in lock-step)."""
        return self._pauser.paused


__all__ = ["Pausable", "Pauser"]
