"""Launcher: starts sim processes on this machine, watches them and stops them.

Runs in the agent process; the local :class:`~remoteenv.agent.launch.sim_group.SimGroup`.
Each sim is ``python <scene script> --address ...`` in a session (process group) of its own, bound to a collision-free address:
an ipc socket in a private temp dir, or tcp on 127.0.0.1 with a port the OS
assigns; it is forked by a zygote that has imported what sims need where one
can be used (:mod:`remoteenv.agent.launch.sim_spawn`, :mod:`~remoteenv.agent.launch.sim_start`), so that it serves in
milliseconds. The launcher waits until each sim reports its bound endpoint (never a
fixed sleep), and stops them on :meth:`close`, on interpreter exit or when it
is garbage collected: SIGTERM to the process group, then SIGKILL, then the
private dir (socket files, logs, delay files) is removed. Each sim also watches this
process (its parent, or its zygote's) and exits if the agent dies.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import weakref
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from remoteenv.agent.connection.connect import SimConnection, connect_sim
from remoteenv.agent.launch.dir_reaper import watch_dir
from remoteenv.agent.launch.layout_gate import GateFacts, LayoutRejected, go, wait_facts
from remoteenv.agent.launch.private_dir import make_private_dir
from remoteenv.agent.launch.processes import pid_alive
from remoteenv.agent.launch.sim_command import wait_ready
from remoteenv.agent.launch.sim_group import LaunchSpec, SimLayout
from remoteenv.agent.launch.sim_process import LaunchState, SimProcess, kill_group, stop_all
from remoteenv.agent.launch.sim_spawn import binds_in_private_dir, sim_address, spawn_sim
from remoteenv.wire.addresses import is_loopback, zmq_transport
from remoteenv.wire.files.keys import KeyPair, generate_keypair
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import ELASTIC

#: The launch arguments of :class:`Launcher` and their defaults (a Launcher
#: made without a scene must leave them alone: :meth:`Launcher.start` gets them).
_LAUNCH_DEFAULTS: dict[str, Any] = {
    "num_instances": 1,
    "seed": None,
    "worlds_per_instance": 1,
    "env_kwargs": None,
    "render_mode": None,
    "startup_timeout": 60.0,
    "real_time": False,
    "real_time_factor": 1.0,
    "real_time_mode": ELASTIC,
    "action_delay": 0,
}


class Launcher:
    """Starts sim processes of one scene on this machine (a
    :class:`~remoteenv.agent.launch.sim_group.SimGroup` that owns its sims).

    ``Launcher(scene, n, ...)`` starts ``n`` sims at once. ``Launcher()``
    without a scene (only the connection options below) starts nothing until
    :meth:`start` gets a :class:`~remoteenv.agent.launch.sim_group.LaunchSpec`: that
    is what an env's ``launcher=`` argument takes.

    Args:
        scene: path of the scene script; None to start later with :meth:`start`.
        num_instances, seed, worlds_per_instance, env_kwargs, render_mode,
        startup_timeout: the launch (see :class:`~remoteenv.agent.launch.sim_group.LaunchSpec`);
            only with ``scene``.
        real_time, real_time_factor, real_time_mode, action_delay: its run
            options (see :class:`~remoteenv.wire.run_options.options.RunOptions`,
            made here once); only with ``scene``.
        transport: ``"ipc"`` (default): each sim binds an ipc endpoint in the
            private dir (made where the sockets' paths fit the OS limit, see
            :func:`~remoteenv.agent.launch.private_dir.make_private_dir`); ``"tcp"``: 127.0.0.1 with an OS-assigned port;
            ``"pipe"``: ipc, and each sim also gets one end of a Unix socketpair
            (the local pipe, :attr:`SimProcess.pipe`), the fastest way for this
            process to talk to it.
        extra_args: more command-line arguments for the scene script.
        bind_host: bind tcp on this interface (OS-assigned port) instead of the
            default. Anything but loopback turns CURVE on and cannot turn it off.
        curve: encrypt and authenticate with ZMQ CURVE. Each sim gets a fresh
            server key pair (secret in the private dir, mode 0600); this
            launcher holds the one client key pair the sims admit
            (:attr:`curve_client_keypair`). Default: on iff ``bind_host`` is
            beyond loopback.
        zygote: fork each sim from this process's zygote for its environment
            (:mod:`remoteenv.agent.launch.zygote`: a process that has imported what
            sims need, so a sim serves in milliseconds instead of most of a
            second). Where none can be used (``REMOTEENV_ZYGOTE=0``, not Linux
            5.3+, ``render_mode="human"``, a refusal) the sim is started the
            plain way, ``python <scene script> ...``. False: always the plain way.
    """

    #: Closing the launcher stops its sims; an env may relaunch them.
    owns_sims = True

    def __init__(
        self,
        scene: str | os.PathLike[str] | None = None,
        num_instances: int = 1,
        *,
        seed: int | None = None,
        worlds_per_instance: int = 1,
        env_kwargs: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        transport: str = "ipc",
        startup_timeout: float = 60.0,
        real_time: bool = False,
        real_time_factor: float = 1.0,
        real_time_mode: str = ELASTIC,
        action_delay: int = 0,
        extra_args: Sequence[str] = (),
        bind_host: str | None = None,
        curve: bool | None = None,
        zygote: bool = True,
    ) -> None:
        launch = {
            "num_instances": num_instances,
            "seed": seed,
            "worlds_per_instance": worlds_per_instance,
            "env_kwargs": env_kwargs,
            "render_mode": render_mode,
            "startup_timeout": startup_timeout,
            "real_time": real_time,
            "real_time_factor": real_time_factor,
            "real_time_mode": real_time_mode,
            "action_delay": action_delay,
        }
        spec = None
        if scene is not None:
            spec = LaunchSpec(
                os.path.abspath(os.fspath(scene)),
                num_instances,
                worlds_per_instance,
                seed=seed,
                env_kwargs=env_kwargs or {},
                render_mode=render_mode,
                run=RunOptions(
                    real_time=real_time,
                    real_time_factor=real_time_factor,
                    real_time_mode=real_time_mode,
                    action_delay=action_delay,
                ),
                startup_timeout=startup_timeout,
            )
            if not os.path.isfile(spec.scene):
                raise FileNotFoundError(f"scene script {spec.scene!r} does not exist")
        else:
            given = sorted(k for k, v in launch.items() if v != _LAUNCH_DEFAULTS[k])
            if given:
                raise TypeError(
                    f"Launcher() without a scene takes no launch arguments (got {', '.join(given)}): "
                    "pass them to start() as a LaunchSpec, or give the scene"
                )
        self.transport = zmq_transport(transport)  # raises for an unknown transport
        #: Whether each sim gets a local pipe to this process.
        self.local_pipe = transport == "pipe"
        self.extra_args = list(extra_args)
        #: Whether sims are forked from a zygote where one can be used.
        self.zygote = bool(zygote)
        self.bind_address: str | None = None
        if bind_host is not None:
            self.transport = "tcp"
            self.bind_address = f"tcp://{bind_host}:*"
        remote = self.bind_address is not None and not is_loopback(self.bind_address)
        if remote and curve is False:
            raise ValueError(f"binding {bind_host!r} (beyond loopback) requires CURVE; drop curve=False")
        self.remote = remote
        #: The client key pair the sims admit, when CURVE is on.
        self.curve_client_keypair: KeyPair | None = generate_keypair() if (remote or bool(curve)) else None
        #: What was started (None until :meth:`start`).
        self.spec: LaunchSpec | None = None
        #: Asked once, by the next :meth:`start`, with what its first sim measured of one
        #: world before building any (:mod:`~remoteenv.agent.launch.layout_gate`): True
        #: lets the sims go on, False stops the launch (:class:`~remoteenv.agent.launch.layout_gate.LayoutRejected`).
        #: None: the sims start without the gate. Restarts never pass it.
        self.layout_gate: Callable[[GateFacts], bool] | None = None
        self._state: LaunchState | None = None
        self._closed = False
        if spec is not None:
            self.start(spec)

    # ------------------------------------------------------------ SimGroup

    def start(self, spec: LaunchSpec) -> None:
        """Start ``spec.num_instances`` sims and wait until each serves its endpoint.

        Raises :class:`remoteenv.LaunchError` naming the instance that failed to
        start (the others are stopped first), and
        :class:`~remoteenv.agent.launch.layout_gate.LayoutRejected` (every sim
        stopped) when :attr:`layout_gate` turns the launch down."""
        if self.spec is not None or self._closed:
            raise RuntimeError("this Launcher has already started its sims; create another one")
        spec = dataclasses.replace(spec, scene=os.path.abspath(spec.scene))
        if not os.path.isfile(spec.scene):
            raise FileNotFoundError(f"scene script {spec.scene!r} does not exist")
        self.spec = spec
        sockets = binds_in_private_dir(self.transport, self.bind_address)
        self._state = LaunchState(workdir=make_private_dir(spec.num_instances, sockets=sockets))
        # Removed even if this process is killed before any sim exists; only this dir, never what replaces it.
        self._state.workdir_id = watch_dir(self._state.workdir)
        self._finalizer = weakref.finalize(self, stop_all, self._state)
        gate, self.layout_gate = self.layout_gate, None
        try:
            for i in range(spec.num_instances):
                self._state.sims.append(self._spawn(i, gated=gate is not None and i == 0))
            if gate is not None:
                self._pass_gate(self._state.sims[0], gate)
            for sim in self._state.sims:
                self._wait_ready(sim)
        except BaseException:
            self.close()
            raise

    @property
    def sims(self) -> list[SimProcess]:
        return [] if self._state is None else self._state.sims

    @property
    def layout(self) -> SimLayout | None:
        """The layout of the started sims; None before :meth:`start`."""
        if self.spec is None:
            return None
        return self.spec.layout(f"the launcher of {os.path.basename(self.spec.scene)}")

    def connect(self, index: int, timeout: float | None) -> SimConnection:
        """A connection to sim ``index``: its local pipe if it has one, else ZeroMQ."""
        return connect_sim(self.sims[index], timeout=timeout, curve_client_keypair=self.curve_client_keypair)

    def restart(self, instance: int) -> SimProcess:
        """Kill instance ``instance`` if it still runs and launch it afresh."""
        state = self._started()
        old = state.sims[instance]
        kill_group(
            old.proc.pid, signal.SIGKILL
        )  # the whole group, even if the sim exited: its orphan guard waits in it
        old.proc.wait()
        old.close_pipe()
        new = self._spawn(instance)
        new.restarts = old.restarts + 1
        state.sims[instance] = new
        self._wait_ready(new)
        return new

    def close(self) -> None:
        """Stop every sim (SIGTERM, then SIGKILL after 2 s) and remove the private dir."""
        self._closed = True
        if self._state is not None:
            self._finalizer()

    @property
    def closed(self) -> bool:
        return self._closed or (self._state is not None and not self._finalizer.alive)

    # ------------------------------------------------------------ more

    @property
    def scene(self) -> str:
        """Absolute path of the scene script the sims run."""
        return self._spec().scene

    @property
    def num_instances(self) -> int:
        return self._spec().num_instances

    @property
    def worlds_per_instance(self) -> int:
        return self._spec().worlds_per_instance

    @property
    def workdir(self) -> str:
        """The private temp dir holding socket files and logs."""
        return self._started().workdir

    @property
    def endpoints(self) -> list[str]:
        return [s.endpoint for s in self.sims if s.endpoint is not None]

    @property
    def pids(self) -> list[int]:
        return [s.pid for s in self.sims]

    def instance_seed(self, instance: int) -> int | None:
        return self._spec().instance_seed(instance)

    def __enter__(self) -> Launcher:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------ internals

    def _spec(self) -> LaunchSpec:
        if self.spec is None:
            raise RuntimeError("this Launcher has not started any sims yet: call start(spec)")
        return self.spec

    def _started(self) -> LaunchState:
        self._spec()
        assert self._state is not None
        return self._state

    def _spawn(self, instance: int, gated: bool = False) -> SimProcess:
        spec = self._spec()
        workdir = self._started().workdir
        extra_args = [*self.extra_args, "--layout-gate", self._gate_file(instance)] if gated else self.extra_args
        return spawn_sim(
            spec,
            instance,
            workdir,
            sim_address(workdir, instance, self.transport, self.bind_address),
            curve_client_keypair=self.curve_client_keypair,
            allow_remote=self.remote,
            extra_args=extra_args,
            local_pipe=self.local_pipe,
            use_zygote=self.zygote and spec.render_mode != "human",
        )

    def _gate_file(self, instance: int) -> str:
        return os.path.join(self._started().workdir, f"sim-{instance}.layout.json")

    def _pass_gate(self, sim: SimProcess, gate: Callable[[GateFacts], bool]) -> None:
        """Read what gated ``sim`` measured; let it go on if ``gate`` agrees, else raise LayoutRejected."""
        spec = self._spec()
        facts = wait_facts(sim, self._gate_file(sim.instance), spec.startup_timeout, os.path.basename(spec.scene))
        if not gate(facts):
            raise LayoutRejected(facts)
        go(sim)

    def _wait_ready(self, sim: SimProcess) -> None:
        spec = self._spec()
        wait_ready(sim, spec.startup_timeout, os.path.basename(spec.scene))


__all__ = ["Launcher", "SimProcess", "pid_alive"]
