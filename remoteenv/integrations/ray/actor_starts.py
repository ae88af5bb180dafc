"""Starting sims on their Ray actors and waiting until they serve.

Runs in the agent process (:class:`~remoteenv.integrations.ray.ray_launcher.RayLauncher`, at
start and on a restart). Every actor gets its sim's fresh CURVE server key
pair (the secret only as a Ray call argument) and the client's public key;
the starts run in parallel, and the wait for them shares one deadline. A
failure becomes a :class:`remoteenv.LaunchError` (a ``RemoteEnvError`` of
kind ``launch``) naming the instance and what happened: no start in time
(and, after a lost node, that no surviving node could take its bundle), the
actor died, or the sim could not start.
"""

from __future__ import annotations

import os
import time
from typing import Any

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.sim_group import LaunchSpec
from remoteenv.integrations.ray.placement import Placement, cluster_capacity
from remoteenv.integrations.ray.ray_sim import RaySim, ray_reason
from remoteenv.wire.files.keys import KeyPair, generate_keypair


def start_sims(
    spec: LaunchSpec,
    instances: list[int],
    actors: list[Any],
    client: KeyPair,
    placement: Placement,
    lost: RaySim | None = None,
    deadline: float | None = None,
) -> list[RaySim]:
    """Start the sims of ``instances`` of ``spec`` on ``actors`` in parallel and
    wait until all are ready (until ``deadline``, default ``startup_timeout``
    from now). ``client``: the key pair the sims admit; ``placement``: for
    messages; ``lost``: the sim whose node was lost, when restarting it."""
    import ray

    scene = os.path.basename(spec.scene)
    servers = [generate_keypair() for _ in instances]
    refs = [a.start.remote(k.secret, client.public) for a, k in zip(actors, servers)]
    if deadline is None:
        deadline = time.monotonic() + spec.startup_timeout
    infos: list[dict[str, Any]] = []
    for instance, ref in zip(instances, refs):
        try:
            infos.append(ray.get(ref, timeout=max(0.0, deadline - time.monotonic())))
        except ray.exceptions.GetTimeoutError:
            message = no_start_message(spec, instance, lost, placement)
            raise RemoteEnvError(message, kind="launch", instance=instance) from None
        except ray.exceptions.RayActorError as exc:
            raise RemoteEnvError(
                f"the Ray actor of sim instance {instance} of {scene} died while starting it: {ray_reason(exc)}",
                kind="launch",
                instance=instance,
            ) from exc
        except ray.exceptions.RayTaskError as exc:
            inner = exc.cause if isinstance(getattr(exc, "cause", None), BaseException) else exc
            text = str(inner) if isinstance(inner, RemoteEnvError) else f"{type(inner).__name__}: {inner}"
            raise RemoteEnvError(
                f"sim instance {instance} of {scene} could not start on the cluster: {text}",
                kind="launch",
                instance=instance,
            ) from None
    sims = []
    for instance, actor, keys, info in zip(instances, actors, servers, infos):
        sim = RaySim(
            instance=instance,
            actor=actor,
            endpoint=info["endpoint"],
            pid=info["pid"],
            node_id=info["node_id"],
            node_ip=info["node_ip"],
            host=info["host"],
            curve_server_key=keys.public,
            generation=info["generation"],
        )
        sim.exit_ref = actor.wait_exit.remote(sim.generation)
        sims.append(sim)
    return sims


def no_start_message(spec: LaunchSpec, instance: int, lost: RaySim | None, placement: Placement) -> str:
    """Why ``instance`` is not up by the deadline, with the cluster's capacity."""
    text = f"sim instance {instance} of {os.path.basename(spec.scene)} did not start within {spec.startup_timeout:g} s"
    if lost is not None and lost.actor_lost:
        text += (
            f" after its node {lost.node} was lost: no surviving node could take its bundle ({placement.describe(1)})"
        )
    return f"{text}. {cluster_capacity()}"


__all__ = ["no_start_message", "start_sims"]
