"""Spawning one sim of a :class:`~remoteenv.agent.launch.launcher.Launcher`:
its address, its files, its command line, its start.

Runs in the agent process. :func:`sim_address` picks where instance ``i``
binds; :func:`spawn_sim` clears what an earlier sim of that instance left in
the private dir (ready file, ipc socket, CURVE key files), writes a fresh
CURVE server key pair and the admitted client key when CURVE is on, builds
the scene command (:mod:`~remoteenv.agent.launch.sim_command`) and starts it
(:mod:`~remoteenv.agent.launch.sim_start`: forked by a zygote or the plain
way). It does not wait for the sim to serve
(:func:`~remoteenv.agent.launch.sim_command.wait_ready` does).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from remoteenv.agent.launch.sim_command import launch_environment, scene_command, write_sim_delay_file
from remoteenv.agent.launch.sim_group import LaunchSpec
from remoteenv.agent.launch.sim_process import SimProcess
from remoteenv.agent.launch.sim_start import start_sim
from remoteenv.wire.addresses import ipc_address, ipc_path, tcp_loopback_address
from remoteenv.wire.files.keys import KeyPair, generate_keypair, write_public_keys, write_secret_key


def binds_in_private_dir(transport: str, bind_address: str | None) -> bool:
    """Whether the sims bind an ipc socket in the launch's private dir (no
    ``bind_address`` given, ``transport`` ``"ipc"``): see :func:`sim_address`."""
    return bind_address is None and transport == "ipc"


def sim_address(workdir: str, instance: int, transport: str, bind_address: str | None) -> str:
    """Where instance ``instance`` binds: ``bind_address`` if given, else an ipc
    socket in ``workdir`` (``transport`` ``"ipc"``) or tcp on loopback with a port the OS assigns."""
    if binds_in_private_dir(transport, bind_address):
        return ipc_address(workdir, instance)
    return bind_address if bind_address is not None else tcp_loopback_address()


def spawn_sim(
    spec: LaunchSpec,
    instance: int,
    workdir: str,
    address: str,
    *,
    curve_client_keypair: KeyPair | None,
    allow_remote: bool,
    extra_args: Sequence[str],
    local_pipe: bool,
    use_zygote: bool,
) -> SimProcess:
    """Start instance ``instance`` of ``spec`` bound to ``address``, its files in
    ``workdir``. ``curve_client_keypair``: CURVE on, admitting that client;
    ``allow_remote``: it may bind beyond loopback; ``extra_args``: more
    arguments for the scene script; ``local_pipe``: give it one end of a
    socketpair; ``use_zygote``: fork it from a zygote where one can be used."""
    ready_file = os.path.join(workdir, f"sim-{instance}.ready.json")
    log_path = os.path.join(workdir, f"sim-{instance}.log")
    for path in (ready_file, ipc_path(address)):
        if path and os.path.exists(path):
            os.unlink(path)
    curve_files = None
    server_key = None
    if curve_client_keypair is not None:
        server = generate_keypair()
        server_key = server.public
        curve_files = (
            os.path.join(workdir, f"sim-{instance}.curve_secret"),
            os.path.join(workdir, f"sim-{instance}.curve_clients"),
        )
        for path in curve_files:
            if os.path.exists(path):
                os.unlink(path)
        write_secret_key(curve_files[0], server.secret)
        write_public_keys(curve_files[1], [curve_client_keypair.public])
    cmd = scene_command(
        spec.scene,
        address,
        instance=instance,
        worlds=spec.worlds_per_instance,
        env_kwargs=dict(spec.env_kwargs),
        parent_pid=os.getpid(),
        ready_file=ready_file,
        private_dir=workdir,
        seed=spec.instance_seed(instance),
        render_mode=spec.render_mode,
        run=spec.run,
        delay_file=write_sim_delay_file(workdir, instance, spec.run.delay_file_text()),
        curve_files=curve_files,
        allow_remote=allow_remote,
        extra_args=list(extra_args),
    )
    started = start_sim(
        cmd,
        env=launch_environment(spec.render_mode),
        log_path=log_path,
        local_pipe=local_pipe,
        use_zygote=use_zygote,
        scene=spec.scene,
        timeout=spec.startup_timeout,
    )
    return SimProcess(
        instance=instance,
        proc=started.proc,
        log_path=log_path,
        ready_file=ready_file,
        curve_server_key=server_key,
        log_offset=started.log_offset,
        pipe=started.pipe,
        zygote_pid=started.zygote_pid,
    )


__all__ = ["binds_in_private_dir", "sim_address", "spawn_sim"]
