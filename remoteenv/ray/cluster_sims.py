"""A group of sims running on a Ray cluster, as the agent sees it.

Runs in the agent process (the Ray driver). One :class:`~remoteenv.ray.sim_actor.SimActor`
per sim process, all in one placement group. The agent makes every CURVE key:
one client key pair for the group (its secret never leaves this process) and
a server key pair per sim, whose secret travels to the sim's actor only as a
Ray call argument. The agent connects to each sim directly over TCP; Ray
carries no env traffic.

A sim's death is learnt from a reply the agent is already waiting for: each
actor's ``wait_exit`` call returns when its sim process exits, and fails
when the actor itself dies (its worker killed, its node lost), so
:meth:`ClusterSim.death` is a non-blocking look at one object ref.
"""

from __future__ import annotations

import os
import time
import weakref
from dataclasses import dataclass, field
from typing import Any, Sequence

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.ray.placement import Placement, cluster_capacity, create_placement_group
from remoteenv.ray.sim_actor import SimActor, SimSpec
from remoteenv.wire.keys import KeyPair, generate_keypair

#: Threads of each actor: ``wait_exit`` holds one for the sim's lifetime.
ACTOR_CONCURRENCY = 4
#: Seconds :meth:`ClusterSims.close` gives the actors to stop their sims.
_STOP_WAIT_S = 5.0


@dataclass
class ClusterSim:
    """One sim process on the cluster: where it listens and how to tell it is gone.

    Has what a connection needs of a sim (``instance``, ``endpoint``,
    ``curve_server_key``, ``death``) plus where it runs."""

    instance: int
    actor: Any
    endpoint: str
    #: The sim's process id on its node.
    pid: int
    node_id: str
    node_ip: str
    host: str
    curve_server_key: bytes
    generation: int
    restarts: int = 0
    #: Cluster sims have no local pipe.
    pipe: None = None
    _exit_ref: Any = field(default=None, repr=False)
    _death: str | None = field(default=None, repr=False)
    #: True once the actor itself is known to be dead (not just its sim).
    actor_lost: bool = False

    def death(self) -> str | None:
        """Why the sim is gone (its exit, or its actor's or node's loss), or None
        while it runs. Never blocks."""
        if self._death is not None:
            return self._death
        import ray

        ready, _ = ray.wait([self._exit_ref], timeout=0)
        if not ready:
            return None
        try:
            self._death = str(ray.get(ready[0]))
        except Exception as exc:  # the actor died: its worker or its node is gone
            self.actor_lost = True
            self._death = (f"its Ray actor on node {self.node_ip} (node id {self.node_id[:12]}) is gone, "
                           f"and the sim with it: {_ray_reason(exc)}")
        return self._death


def _ray_reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:300] + ("..." if len(text) > 300 else "")


def _kill_actor(actor: Any) -> None:
    import ray

    try:
        ray.kill(actor, no_restart=True)
    except Exception:
        pass


def _unwrap(exc: BaseException) -> BaseException:
    """The error a remote call raised inside its actor, if Ray wrapped one."""
    cause = getattr(exc, "cause", None)
    return cause if isinstance(cause, BaseException) else exc


@dataclass
class _State:
    """What the finalizer needs; holds no reference to the group."""

    sims: list[ClusterSim] = field(default_factory=list)
    placement_group: Any = None


def _remove_all(state: _State) -> None:
    import ray

    if not ray.is_initialized():
        return
    from ray.util.placement_group import remove_placement_group

    stops = []
    for sim in state.sims:
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


class ClusterSims:
    """Starts ``num_instances`` sims of one scene on the Ray cluster this process is connected to.

    Args:
        scene: a shipped scene's name, or the path of a scene script as the
            nodes see it (see :func:`remoteenv.ray.sim_actor.resolve_scene`).
        num_instances: sim processes.
        placement: where they may run.
        seed: instance ``i`` gets ``seed + i * worlds_per_instance``.
        worlds_per_instance, env_kwargs, render_mode, real_time,
        real_time_factor, action_delay, extra_args, startup_timeout: as for
            :class:`remoteenv.Launcher`. ``startup_timeout`` bounds the
            placement and each sim's start separately.
        runtime_env: Ray runtime environment of the actors (and so of the
            sims), e.g. ``{"working_dir": "my_scenes"}`` to ship a scene.
    """

    #: The env asks these sims to exit when it closes (they are its own).
    attached = False

    def __init__(
        self,
        scene: str,
        num_instances: int,
        placement: Placement,
        *,
        seed: int | None = None,
        worlds_per_instance: int = 1,
        env_kwargs: dict[str, Any] | None = None,
        render_mode: str | None = None,
        real_time: bool = False,
        real_time_factor: float = 1.0,
        action_delay: int = 0,
        extra_args: Sequence[str] = (),
        startup_timeout: float = 60.0,
        runtime_env: dict[str, Any] | None = None,
    ) -> None:
        import ray

        if num_instances < 1 or worlds_per_instance < 1:
            raise ValueError("num_instances and worlds_per_instance must be >= 1")
        self.scene = scene
        self.num_instances = num_instances
        self.worlds_per_instance = worlds_per_instance
        self.seed = seed
        self.placement = placement
        self.startup_timeout = startup_timeout
        self.runtime_env = runtime_env
        self.real_time = real_time
        self.action_delay = action_delay
        self._spec = dict(worlds=worlds_per_instance, env_kwargs=dict(env_kwargs or {}), render_mode=render_mode,
                          real_time=real_time, real_time_factor=real_time_factor, action_delay=action_delay,
                          extra_args=tuple(extra_args), startup_timeout=startup_timeout)
        #: The client key pair the sims admit; its secret stays in this process.
        self.curve_client_keypair: KeyPair = generate_keypair()
        self._actor_class = ray.remote(SimActor)
        self._state = _State()
        self._finalizer = weakref.finalize(self, _remove_all, self._state)
        try:
            self._state.placement_group = create_placement_group(placement, num_instances, startup_timeout)
            actors = [self._new_actor(i) for i in range(num_instances)]
            self._state.sims.extend(self._start(list(range(num_instances)), actors))
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ public

    @property
    def sims(self) -> list[ClusterSim]:
        return self._state.sims

    @property
    def endpoints(self) -> list[str]:
        return [s.endpoint for s in self._state.sims]

    @property
    def pids(self) -> list[int]:
        """Each sim's process id on its own node."""
        return [s.pid for s in self._state.sims]

    @property
    def node_ids(self) -> list[str]:
        """The Ray node id each instance runs on."""
        return [s.node_id for s in self._state.sims]

    @property
    def placement_group(self) -> Any:
        return self._state.placement_group

    @property
    def timed_steps(self) -> bool:
        return bool(self.real_time or self.action_delay)

    def instance_seed(self, instance: int) -> int | None:
        return None if self.seed is None else self.seed + instance * self.worlds_per_instance

    def restart(self, instance: int) -> ClusterSim:
        """Relaunch instance ``instance``: on its actor if that still lives, else
        on a new actor in the same bundle, which Ray re-places on a surviving
        node once it has declared the old node dead. Raises
        :class:`RemoteEnvError` (kind ``"launch"``) naming the lost node if no
        sim is up within ``startup_timeout``."""
        import ray

        old = self._state.sims[instance]
        old.death()
        actor = old.actor
        deadline = time.monotonic() + self.startup_timeout
        while True:
            if old.actor_lost or actor is not old.actor:
                _kill_actor(actor)
                actor = self._new_actor(instance)
            try:
                (new,) = self._start([instance], [actor], lost=old, deadline=deadline)
                break
            except RemoteEnvError as err:
                # A new actor placed on the lost node before Ray declared it dead
                # dies with it: try again on the bundle's next placement.
                if not isinstance(err.__cause__, ray.exceptions.RayActorError) or time.monotonic() > deadline:
                    _kill_actor(actor)
                    raise
                old.actor_lost = True
        new.restarts = old.restarts + 1
        self._state.sims[instance] = new
        return new

    def kill(self, instance: int) -> None:
        """SIGKILL instance ``instance``'s sim process (for fault tests)."""
        import ray

        ray.get(self._state.sims[instance].actor.kill.remote())

    def close(self) -> None:
        """Stop every sim, end every actor and remove the placement group."""
        self._finalizer()

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    def __enter__(self) -> ClusterSims:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------ internals

    def _new_actor(self, instance: int) -> Any:
        from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

        spec = SimSpec(scene=self.scene, instance=instance, seed=self.instance_seed(instance), **self._spec)
        options: dict[str, Any] = dict(
            num_cpus=self.placement.num_cpus_per_process,
            resources={k: v for k, v in self.placement.resources_per_process.items() if k != "GPU"},
            num_gpus=self.placement.resources_per_process.get("GPU", 0),
            max_concurrency=ACTOR_CONCURRENCY,
            max_restarts=0,
            scheduling_strategy=PlacementGroupSchedulingStrategy(
                self._state.placement_group, placement_group_bundle_index=instance),
        )
        if self.placement.num_cpus_per_process == 0:
            options["num_cpus"] = 0.001
        if self.runtime_env is not None:
            options["runtime_env"] = self.runtime_env
        return self._actor_class.options(**options).remote(spec)

    def _start(self, instances: list[int], actors: list[Any], lost: ClusterSim | None = None,
               deadline: float | None = None) -> list[ClusterSim]:
        """Start the sims of ``instances`` on ``actors`` in parallel and wait until
        all are ready (until ``deadline``, default ``startup_timeout`` from now)."""
        import ray

        servers = [generate_keypair() for _ in instances]
        client = self.curve_client_keypair.public
        refs = [a.start.remote(k.secret, client) for a, k in zip(actors, servers)]
        if deadline is None:
            deadline = time.monotonic() + self.startup_timeout
        infos: list[dict[str, Any]] = []
        for instance, ref in zip(instances, refs):
            try:
                infos.append(ray.get(ref, timeout=max(0.0, deadline - time.monotonic())))
            except ray.exceptions.GetTimeoutError:
                raise RemoteEnvError(self._no_start_message(instance, lost), kind="launch",
                                     instance=instance) from None
            except ray.exceptions.RayTaskError as exc:
                inner = _unwrap(exc)
                if isinstance(inner, RemoteEnvError):
                    raise type(inner)(str(inner), kind="launch", instance=instance) from None
                raise RemoteEnvError(f"sim instance {instance} of {os.path.basename(self.scene)} could not start "
                                     f"on the cluster: {type(inner).__name__}: {inner}",
                                     kind="launch", instance=instance) from None
            except ray.exceptions.RayActorError as exc:
                raise RemoteEnvError(f"the Ray actor of sim instance {instance} died while starting it: "
                                     f"{_ray_reason(exc)}", kind="launch", instance=instance) from exc
        sims = []
        for instance, actor, keys, info in zip(instances, actors, servers, infos):
            sim = ClusterSim(instance=instance, actor=actor, endpoint=info["endpoint"], pid=info["pid"],
                             node_id=info["node_id"], node_ip=info["node_ip"], host=info["host"],
                             curve_server_key=keys.public, generation=info["generation"])
            sim._exit_ref = actor.wait_exit.remote(sim.generation)
            sims.append(sim)
        return sims

    def _no_start_message(self, instance: int, lost: ClusterSim | None) -> str:
        text = f"sim instance {instance} of {os.path.basename(self.scene)} did not start within " \
               f"{self.startup_timeout:g} s"
        if lost is not None and lost.actor_lost:
            text += (f" after its node {lost.node_ip} (node id {lost.node_id[:12]}) was lost: no surviving "
                     f"node could take its bundle ({self.placement.describe(1)})")
        return f"{text}. {cluster_capacity()}"
