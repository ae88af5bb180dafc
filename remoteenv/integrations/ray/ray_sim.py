"""The agent's handle on one sim running on a Ray cluster.

Runs in the agent process (the Ray driver). A handle says where the sim
listens and on which node, and whether it is gone. It learns of a death from
a reply the agent is already waiting for: the sim's actor answers its
``wait_exit`` call when the sim process exits, and the call fails when the
actor itself dies (its worker killed, its node lost). :meth:`RaySim.death` is
a non-blocking look at that one object ref.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


def ray_reason(exc: BaseException, limit: int = 300) -> str:
    """Ray's message for ``exc`` on one line, at most ``limit`` characters."""
    text = " ".join(str(exc).split())
    return text[:limit] + ("..." if len(text) > limit else "")


@dataclass
class RaySim:
    """One sim process on the cluster (a :class:`remoteenv.agent.launch.sim_group.SimHandle`).

    Attributes:
        instance: the sim's index in its group.
        actor: the handle of the Ray actor that runs it.
        endpoint: where the sim listens (``tcp://<node ip>:<port>``).
        pid: the sim's process id on its node.
        node_id: the Ray id of its node.
        node_ip: the address of its node.
        host: its node's host name.
        curve_server_key: the sim's public Z85 CURVE key.
        generation: how many sims the actor has started, this one included.
        restarts: relaunches of this instance so far.
        actor_lost: True once the actor itself is known to be gone.
    """

    instance: int
    actor: Any
    endpoint: str
    pid: int
    node_id: str
    node_ip: str
    host: str
    curve_server_key: bytes
    generation: int
    restarts: int = 0
    actor_lost: bool = False
    exit_ref: Any = field(default=None, repr=False)
    _death: str | None = field(default=None, repr=False)

    @property
    def pipe(self) -> None:
        """Sims on a cluster have no local pipe."""
        return None

    @property
    def node(self) -> str:
        """The node the sim runs on: its address and Ray node id."""
        return f"{self.node_ip} (Ray node {self.node_id[:12]})"

    def death(self) -> str | None:
        """Why the sim is gone (its exit, or its actor's or node's loss), or None
        while it runs. Never blocks."""
        if self._death is not None:
            return self._death
        import ray

        ready, _ = ray.wait([self.exit_ref], timeout=0)
        if not ready:
            return None
        try:
            self._death = str(ray.get(ready[0]))
        except Exception as exc:  # the actor is gone: its worker or its node died
            self.actor_lost = True
            self._death = f"its Ray actor on node {self.node} is gone, and the sim with it: {ray_reason(exc)}"
        return self._death
