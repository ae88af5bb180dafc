"""Gang-scheduling a group of sims on a Ray cluster: one placement group,
one bundle per sim process.

Runs in the agent process (the Ray driver). A placement group reserves every
sim's resources at once (all or nothing), so a group never starts half its
sims and waits for the rest. It is created without ``lifetime="detached"``:
Ray removes it, with the actors in it, when the driver exits.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from remoteenv.agent.errors import RemoteEnvError

#: Ray's placement strategies: PACK (few nodes, best effort), SPREAD (distinct
#: nodes, best effort), STRICT_PACK (one node), STRICT_SPREAD (one node per sim).
STRATEGIES = ("PACK", "SPREAD", "STRICT_PACK", "STRICT_SPREAD")


@dataclass(frozen=True)
class Placement:
    """Where the sims of a group may run.

    Attributes:
        strategy: one of :data:`STRATEGIES`.
        num_cpus_per_process: CPUs reserved for each sim process (its actor
            holds the reservation; the sim process uses it).
        resources_per_process: more Ray resources per sim, e.g. ``{"GPU": 0.25}``
            or a custom resource such as ``{"sim_host": 1}``.
        label_selector: node labels every sim's node must carry, e.g.
            ``{"sim-pool": "mujoco"}`` (nodes get labels from ``ray start --labels``).
    """

    strategy: str = "PACK"
    num_cpus_per_process: float = 1.0
    resources_per_process: Mapping[str, float] = field(default_factory=dict)
    label_selector: Mapping[str, str] | None = None

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ValueError(f"strategy must be one of {STRATEGIES}, got {self.strategy!r}")
        if self.num_cpus_per_process < 0:
            raise ValueError(f"num_cpus_per_process must be >= 0, got {self.num_cpus_per_process}")
        for name, amount in self.resources_per_process.items():
            if name == "CPU":
                raise ValueError("give CPUs as num_cpus_per_process, not in resources_per_process")
            if amount < 0:
                raise ValueError(f"resource {name!r} must be >= 0, got {amount}")

    def bundle(self) -> dict[str, float]:
        """The resources of one sim's bundle (Ray rejects an empty bundle, so
        zero CPUs become a sliver)."""
        bundle = {"CPU": float(self.num_cpus_per_process) or 0.001}
        bundle.update({k: float(v) for k, v in self.resources_per_process.items() if v})
        return bundle

    def describe(self, count: int) -> str:
        text = f"{count} x {self.bundle()} with strategy {self.strategy}"
        if self.label_selector:
            text += f" on nodes labelled {dict(self.label_selector)}"
        return text


def create_placement_group(placement: Placement, count: int, timeout: float) -> Any:
    """Reserve ``count`` bundles and wait up to ``timeout`` seconds until all are placed.

    Raises :class:`RemoteEnvError` (kind ``"launch"``) naming what was asked
    and what the cluster has free when the reservation cannot be made in time."""
    import ray
    from ray.util.placement_group import placement_group, remove_placement_group

    selector = None if placement.label_selector is None else [dict(placement.label_selector)] * count
    group = placement_group(
        [placement.bundle() for _ in range(count)], strategy=placement.strategy, bundle_label_selector=selector
    )
    ready, _ = ray.wait([group.ready()], timeout=timeout)
    if not ready:
        remove_placement_group(group)
        raise RemoteEnvError(
            f"the Ray cluster could not place {placement.describe(count)} within {timeout:g} s. "
            f"{cluster_capacity()} Add nodes, lower num_cpus_per_process, or choose a looser strategy.",
            kind="launch",
        )
    return group


def cluster_capacity() -> str:
    """One line saying which nodes are alive and what each has free (for error messages)."""
    import ray

    free = ray.available_resources()
    nodes = [n for n in ray.nodes() if n.get("Alive")]
    parts = [f"{n['NodeManagerAddress']} ({n['NodeID'][:12]}): {n['Resources'].get('CPU', 0):g} CPUs" for n in nodes]
    return f"The cluster has {len(nodes)} live node(s) [{'; '.join(parts)}] and {free.get('CPU', 0):g} CPUs unreserved."


def bundle_node(group: Any, index: int) -> str | None:
    """The Ray node id bundle ``index`` of ``group`` is placed on, or None if it is unplaced."""
    from ray.util import placement_group_table

    table = placement_group_table(group)
    return (table.get("bundles_to_node_id") or {}).get(index)
