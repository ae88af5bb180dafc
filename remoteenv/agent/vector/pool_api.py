"""EnvPool's asynchronous API (``send``/``recv``) on :class:`remoteenv.RemoteVectorEnv`.

Runs in the agent process; the work is :mod:`~remoteenv.agent.vector.vector_async`'s,
reached through the env's :class:`~remoteenv.agent.vector.vector_episodes.VectorEpisodes`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from remoteenv.agent.vector.vector_episodes import VectorEpisodes
from remoteenv.wire.messages.batch_encoding import AddInfo


class PoolAPI:
    """Mixin for a vector env with ``self._episodes`` and Gymnasium's ``_add_info``."""

    _episodes: VectorEpisodes
    _add_info: AddInfo

    def send(self, actions: Any, env_ids: Any = None) -> None:
        """EnvPool's asynchronous step: send ``actions[j]`` to world ``env_ids[j]``
        (default: every world) and return at once; :meth:`recv` returns results.

        A world must not be in flight (sent and not yet received). Lock-step
        only. A failing sim raises from :meth:`recv`, which then forgets what
        was in flight: call ``reset`` before stepping again (restarts
        cover ``step`` only)."""
        self._episodes.send(actions, env_ids)

    def recv(self) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """The first ``batch_size`` worlds to finish after :meth:`send`:
        ``(obs, rewards, terminated, truncated, infos)`` with ``batch_size`` rows,
        world ``infos["env_id"][j]`` in row ``j``, autoreset as in ``step``."""
        return self._episodes.recv(self._add_info)


__all__ = ["PoolAPI"]
