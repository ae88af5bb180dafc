"""RayLauncher: an env's sims placed on a Ray cluster.

Runs in the agent process, which becomes a Ray driver. One
:class:`~remoteenv.integrations.ray.sim_actor.SimActor` per sim process, all in one
placement group; each actor starts its sim bound to TCP on its node with
CURVE on, and the agent connects to the sims directly (Ray carries no env
traffic). The agent makes every CURVE key: one client key pair (its secret
never leaves this process) and a server key pair per sim, whose secret
travels to the sim's actor only as a Ray call argument.

Nothing outlives the driver: the actors and the placement group are not
detached, so Ray removes them when this process exits, however it exits, and
each sim exits when its actor does (it watches its parent).
"""

from __future__ import annotations

import os
import time
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from remoteenv.agent.connection.connect import SimConnection, connect_sim
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.sim_group import LaunchSpec, SimLayout
from remoteenv.integrations.ray.actor_starts import start_sims
from remoteenv.integrations.ray.placement import Placement, create_placement_group
from remoteenv.integrations.ray.ray_sim import RaySim
from remoteenv.integrations.ray.sim_actor import SimActor, SimSpec, shipped_scenes_dir
from remoteenv.wire.files.keys import KeyPair, generate_keypair

#: Threads of each actor: ``wait_exit`` holds one for as long as its sim runs.
ACTOR_CONCURRENCY = 4
#: Seconds :meth:`RayLauncher.close` gives the actors to stop their sims.
_STOP_WAIT_S = 5.0


def scene_on_nodes(scene: str) -> str:
    """What to ask the nodes for: a shipped scene's name when ``scene`` is the
    script of a shipped scene (the nodes have their own copy, wherever their
    remoteenv is installed), else ``scene`` unchanged."""
    folder = shipped_scenes_dir()
    path = os.path.abspath(scene)
    name = os.path.basename(os.path.dirname(path))
    if os.path.dirname(os.path.dirname(path)) == folder and os.path.basename(path) == f"{name}_scene.py":
        return name
    return scene


def _kill_actor(actor: Any) -> None:
    import ray

    try:
        ray.kill(actor, no_restart=True)
    except Exception:
        pass


@dataclass
class _State:
    """What the finalizer needs; holds no reference to the launcher."""

    sims: list[RaySim] = field(default_factory=list)
    placement_group: Any = None


def _remove_all(state: _State) -> None:
    """Stop the sims, end the actors, remove the placement group."""
    import ray

    if not ray.is_initialized():
        return  # Ray is shut down: it has removed them already
    from ray.util.placement_group import remove_placement_group

    stops = []
    for sim in state.sims:
        if not sim.actor_lost:
            try:
                stops.append(sim.actor.stop.remote())
            except Exception:
                pass
    if stops:
        ray.wait(stops, num_returns=len(stops), timeout=_STOP_WAIT_S)
    for sim in state.sims:
        _kill_actor(sim.actor)
    if state.placement_group is not None:
        try:
            remove_placement_group(state.placement_group)
        except Exception:
            pass
        state.placement_group = None


class RayLauncher:
    """Places an env's sims on a Ray cluster (a :class:`~remoteenv.agent.launch.sim_group.SimGroup`).

    Pass one to an env's ``launcher=``::

        envs = gym.make_vec("remoteenv/Reacher-v0", num_envs=64, vectorization_mode="vector_entry_point",
                            envs_per_process=8, launcher=RayLauncher(strategy="SPREAD"))

    If this process is not yet connected to Ray, :meth:`start` calls
    ``ray.init(address)``: with no address that joins the cluster named by
    ``RAY_ADDRESS`` or running on this machine, else starts a local one.

    Args:
        strategy: Ray placement strategy: ``"PACK"`` (few nodes), ``"SPREAD"``
            (distinct nodes where possible), ``"STRICT_PACK"`` (one node),
            ``"STRICT_SPREAD"`` (one node per sim).
        num_cpus_per_process: CPUs reserved for each sim process.
        resources_per_process: more Ray resources per sim process, e.g.
            ``{"GPU": 0.25}`` or a custom resource ``{"mujoco_host": 1}``.
        label_selector: node labels each sim's node must carry (``ray start --labels``).
        runtime_env: Ray runtime environment of the actors and so of the sims,
            e.g. ``{"working_dir": "my_scene/"}`` to ship a scene script that
            is not installed on the nodes (see docs/cluster.md).
        address: the cluster to join if Ray is not initialized yet.
        extra_args: more command-line arguments for the scene script.

    A launcher starts one group of sims, once (:meth:`start`); an env that
    closes closes it.
    """

    #: Closing the launcher stops its sims; an env may relaunch them.
    owns_sims = True

    def __init__(
        self,
        *,
        strategy: str = "PACK",
        num_cpus_per_process: float = 1.0,
        resources_per_process: Mapping[str, float] | None = None,
        label_selector: Mapping[str, str] | None = None,
        runtime_env: Mapping[str, Any] | None = None,
        address: str | None = None,
        extra_args: Sequence[str] = (),
    ) -> None:
        self.placement = Placement(
            strategy,
            num_cpus_per_process,
            dict(resources_per_process or {}),
            None if label_selector is None else dict(label_selector),
        )
        self.runtime_env = None if runtime_env is None else dict(runtime_env)
        self.address = address
        self.extra_args = tuple(extra_args)
        #: The client key pair the sims admit; its secret stays in this process.
        self.curve_client_keypair: KeyPair = generate_keypair()
        #: What was started (None until :meth:`start`).
        self.spec: LaunchSpec | None = None
        self._state = _State()
        self._finalizer: weakref.finalize | None = None
        self._closed = False
        self._actor_class: Any = None
        #: Hex id of the placement group once reserved (it stays set after close).
        self.placement_group_id: str | None = None

    # ------------------------------------------------------------ SimGroup

    def start(self, spec: LaunchSpec) -> None:
        """Reserve the placement group, start one actor and sim per instance in
        parallel, and return once every sim serves its endpoint. Raises
        :class:`remoteenv.LaunchError` saying what could not be placed or
        which instance failed (after removing everything started)."""
        import ray

        if self.spec is not None or self._closed:
            raise RuntimeError("this RayLauncher has already started its sims; create another one")
        if not ray.is_initialized():
            ray.init(address=self.address)
        self.spec = spec
        self._actor_class = ray.remote(SimActor)
        self._finalizer = weakref.finalize(self, _remove_all, self._state)
        try:
            self._state.placement_group = create_placement_group(
                self.placement, spec.num_instances, spec.startup_timeout
            )
            self.placement_group_id = self._state.placement_group.id.hex()
            instances = list(range(spec.num_instances))
            self._state.sims.extend(self._start(instances, [self._new_actor(i) for i in instances]))
        except BaseException:
            self.close()
            raise

    @property
    def sims(self) -> list[RaySim]:
        return self._state.sims

    @property
    def layout(self) -> SimLayout | None:
        """The layout of the started sims; None before :meth:`start`."""
        if self.spec is None:
            return None
        return self.spec.layout(f"the RayLauncher of {os.path.basename(self.spec.scene)}")

    def connect(self, index: int, timeout: float | None) -> SimConnection:
        """A CURVE-encrypted ZeroMQ connection to sim ``index``."""
        return connect_sim(self.sims[index], timeout=timeout, curve_client_keypair=self.curve_client_keypair)

    def restart(self, index: int) -> RaySim:
        """Relaunch sim ``index``: on its actor if that still lives, else on a
        new actor in the same bundle, which Ray re-places on a surviving node
        once it has declared the old node dead. Raises
        :class:`remoteenv.LaunchError` naming the lost node if no sim is up
        within the spec's ``startup_timeout``."""
        import ray

        spec = self._spec()
        old = self._state.sims[index]
        old.death()
        actor = old.actor
        deadline = time.monotonic() + spec.startup_timeout
        while True:
            if old.actor_lost or actor is not old.actor:
                _kill_actor(actor)
                actor = self._new_actor(index)
            try:
                (new,) = self._start([index], [actor], lost=old, deadline=deadline)
                break
            except RemoteEnvError as err:
                # A new actor that Ray placed on the lost node before declaring
                # it dead dies with it: try again on the bundle's next placement.
                if not isinstance(err.__cause__, ray.exceptions.RayActorError) or time.monotonic() > deadline:
                    _kill_actor(actor)
                    raise
                old.actor_lost = True
        new.restarts = old.restarts + 1
        self._state.sims[index] = new
        return new

    def close(self) -> None:
        """Stop every sim, end every actor and remove the placement group; idempotent."""
        self._closed = True
        if self._finalizer is not None:
            self._finalizer()

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------ more

    @property
    def endpoints(self) -> list[str]:
        return [s.endpoint for s in self.sims]

    @property
    def pids(self) -> list[int]:
        """Each sim's process id on its own node."""
        return [s.pid for s in self.sims]

    @property
    def node_ids(self) -> list[str]:
        """The Ray node id each instance runs on."""
        return [s.node_id for s in self.sims]

    @property
    def placement_group(self) -> Any:
        """The Ray placement group holding the sims' bundles (None once closed)."""
        return self._state.placement_group

    def kill(self, index: int) -> None:
        """SIGKILL sim ``index``'s process on its node (to test fault handling)."""
        import ray

        ray.get(self.sims[index].actor.kill.remote())

    def __enter__(self) -> RayLauncher:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------ internals

    def _spec(self) -> LaunchSpec:
        if self.spec is None:
            raise RuntimeError("this RayLauncher has not started any sims yet: call start(spec)")
        return self.spec

    def _new_actor(self, instance: int) -> Any:
        from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

        spec = self._spec()
        sim_spec = SimSpec(
            scene=scene_on_nodes(spec.scene),
            instance=instance,
            worlds=spec.worlds_per_instance,
            seed=spec.instance_seed(instance),
            env_kwargs=dict(spec.env_kwargs),
            render_mode=spec.render_mode,
            # Whole: every delay (action, observation, link) reaches the sim
            # as a file on its node, written by the actor.
            run=spec.run,
            extra_args=self.extra_args,
            startup_timeout=spec.startup_timeout,
        )
        bundle = self.placement.bundle()
        options: dict[str, Any] = dict(
            num_cpus=bundle.pop("CPU"),
            num_gpus=bundle.pop("GPU", 0),
            resources=bundle,
            max_concurrency=ACTOR_CONCURRENCY,
            max_restarts=0,
            scheduling_strategy=PlacementGroupSchedulingStrategy(
                self._state.placement_group, placement_group_bundle_index=instance
            ),
        )
        if self.runtime_env is not None:
            options["runtime_env"] = self.runtime_env
        return self._actor_class.options(**options).remote(sim_spec)

    def _start(
        self, instances: list[int], actors: list[Any], lost: RaySim | None = None, deadline: float | None = None
    ) -> list[RaySim]:
        """Start the sims of ``instances`` on ``actors`` in parallel and wait until
        all are ready (:func:`~remoteenv.integrations.ray.actor_starts.start_sims`)."""
        spec = self._spec()
        return start_sims(spec, instances, actors, self.curve_client_keypair, self.placement, lost, deadline)
