"""A local multi-node Ray cluster for the tests in this folder.

Run them with ``tests/ray/run.sh`` (their own venv, a private network
namespace). They are not part of the main suite: without Ray installed this
folder collects nothing.
"""

from __future__ import annotations

import os
import time
from typing import Any

import pytest

try:
    import ray
    from ray.cluster_utils import Cluster
except ImportError:  # the main test venv has no Ray: skip this folder
    if os.environ.get("REMOTEENV_RAY_SUITE"):  # tests/ray/run.sh's venv must have it: never skip silently
        raise
    collect_ignore_glob = ["test_*.py"]
    ray = None

#: Ray's node failure detector, made fast enough for a test to wait for it:
#: a node that misses 3 health checks 0.5 s apart is declared dead.
FAST_NODE_FAILURE = {
    "health_check_period_ms": 500,
    "health_check_failure_threshold": 3,
    "health_check_initial_delay_ms": 0,
}
#: Ray starts its workers (and so the sims its actors start) at nice 15, which
#: beside two CPU hogs leaves an RLlib env runner a few per cent of a CPU; the
#: suite must pass beside such load, so the workers run at the usual priority.
WORKER_NICENESS = {"worker_niceness": 0}
#: CPUs of the head and of each of the two worker nodes.
HEAD_CPUS = 1
WORKER_CPUS = 2


class TestCluster:
    """A head and two worker nodes on this machine, and the driver connected to it."""

    def __init__(self) -> None:
        #: The ``pool`` label of each worker node, by node id.
        self.pools: dict[str, str] = {}
        self.cluster = Cluster(
            initialize_head=True,
            head_node_args={"num_cpus": HEAD_CPUS, "_system_config": FAST_NODE_FAILURE | WORKER_NICENESS},
        )
        self.workers: list[Any] = []
        while len(self.workers) < 2:
            self.workers.append(self._add_worker())
        ray.init(address=self.cluster.address)
        self.cluster.wait_for_nodes()

    @property
    def head_node_id(self) -> str:
        return self.cluster.head_node.node_id

    def alive_node_ids(self) -> set[str]:
        return {n["NodeID"] for n in ray.nodes() if n["Alive"]}

    def worker_node(self, node_id: str) -> Any:
        """The worker node with Ray id ``node_id`` (never the head: it cannot be removed)."""
        return next(n for n in self.workers if n.node_id == node_id)

    def remove_worker(self, node: Any) -> None:
        """Kill a worker node's raylet and its workers outright, as a crashed machine would."""
        self.workers.remove(node)
        self.cluster.remove_node(node, allow_graceful=False)

    def restore(self) -> None:
        """Add worker nodes until there are two again."""
        while len(self.workers) < 2:
            self.workers.append(self._add_worker())
        self.cluster.wait_for_nodes()

    def _add_worker(self) -> Any:
        """A worker node labelled ``pool=a``, or ``pool=b`` if an ``a`` node is up already."""
        pool = "b" if "a" in {self.pools[n.node_id] for n in self.workers} else "a"
        node = self.cluster.add_node(num_cpus=WORKER_CPUS, labels={"pool": pool})
        self.pools[node.node_id] = pool
        return node

    def shutdown(self) -> None:
        ray.shutdown()
        self.cluster.shutdown()


@pytest.fixture(scope="session")
def cluster():
    c = TestCluster()
    try:
        yield c
    finally:
        c.shutdown()


def assert_nothing_left(launcher: Any, timeout: float = 10.0) -> None:
    """No actor, sim process or placement group of ``launcher`` remains."""
    from ray.util import placement_group_table
    from ray.util.state import list_actors

    actor_ids = {s.actor._actor_id.hex() for s in launcher.sims}
    pids = list(launcher.pids)
    group_id = launcher.placement_group_id
    deadline = time.monotonic() + timeout
    while True:
        live = [
            a
            for a in list_actors(filters=[("class_name", "=", "SimActor")])
            if a.actor_id in actor_ids and a.state != "DEAD"
        ]
        running = [p for p in pids if os.path.exists(f"/proc/{p}") and _not_zombie(p)]
        group = placement_group_table().get(group_id, {}).get("state", "REMOVED")
        if not live and not running and group == "REMOVED":
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"left behind: actors {live}, sim pids {running}, placement group {group}")
        time.sleep(0.1)


@pytest.fixture(name="assert_nothing_left")
def assert_nothing_left_fixture():
    """The function ``assert_nothing_left(launcher, timeout=10.0)`` (tests cannot import conftest)."""
    return assert_nothing_left


def _not_zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
