"""The Ray actor that runs one sim process on a cluster node.

Runs in a Ray worker process on whichever node the placement group put it.
The actor starts the scene script as its child, bound to TCP on the node's
address with an OS-chosen port and CURVE on, waits for the child's ready
file, and reports where it listens. It keeps the child's stderr in a private
dir on the node for error messages, and writes its delay specs there (they
arrive whole, in the run options of this actor's construction, so they reach
the node through Ray; see :mod:`remoteenv.wire.delays.delay_file`). The child watches the actor as its
parent (``--parent-pid``): if the actor dies, however it dies, the child
exits within about a second (see :mod:`remoteenv.sim.process.orphan`).

The actor is threaded (``max_concurrency`` > 1): :meth:`SimActor.wait_exit`
blocks one thread until the child exits, so the agent learns of a sim's death
from a reply it is already waiting for instead of polling the node, while
the other methods stay callable.

Nothing here is Ray-specific except where the node's identity comes from:
the class is wrapped with ``ray.remote`` by :mod:`remoteenv.integrations.ray.ray_launcher`.
"""

from __future__ import annotations

import importlib
import os
import signal
import socket
import subprocess
import tempfile
import threading
from dataclasses import dataclass, field
from typing import Any

from remoteenv.agent.launch.sim_command import scene_command, wait_ready, write_sim_delay_file
from remoteenv.agent.launch.sim_process import SimProcess
from remoteenv.wire.addresses import is_loopback
from remoteenv.wire.files.keys import check_key, write_public_keys, write_secret_key
from remoteenv.wire.files.owned_dirs import identity, remove_dir
from remoteenv.wire.run_options.options import RunOptions

#: Seconds a stopping child gets between SIGTERM and SIGKILL.
STOP_GRACE_S = 2.0


@dataclass(frozen=True)
class SimSpec:
    """What one actor needs to start its sim: plain data, sent through Ray.

    Attributes:
        scene: a shipped scene's name (``"cartpole"``) or the path of a scene
            script that exists on the node (absolute, or relative to the
            actor's working dir, which is the runtime_env's ``working_dir``
            when one is given).
        instance: this sim's index in its group (names it in errors and files).
        worlds: MuJoCo worlds the sim hosts.
        seed: seed of the sim's first world (world w gets seed + w), or None.
        env_kwargs: JSON-able keyword arguments of the scene's env class.
        render_mode: as for :class:`remoteenv.Launcher`.
        run: the sim's run options
            (:class:`~remoteenv.wire.run_options.options.RunOptions`, as the
            launch's :class:`~remoteenv.agent.launch.sim_group.LaunchSpec` holds
            them); the actor writes their delays into a delay file next to its sim.
        extra_args: more command-line arguments for the scene script.
        startup_timeout: seconds to wait for the child's ready file.
    """

    scene: str
    instance: int
    worlds: int = 1
    seed: int | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    render_mode: str | None = None
    run: RunOptions = field(default_factory=RunOptions)
    extra_args: tuple[str, ...] = ()
    startup_timeout: float = 60.0


def shipped_scenes_dir() -> str:
    """The folder of the scenes that ship with this remoteenv installation."""
    # By name: the package lives in the repository's scenes/ folder, outside the
    # tree the import contracts map, which would count this as importing remoteenv.
    scenes = importlib.import_module("remoteenv.scenes")
    return os.path.dirname(os.path.abspath(scenes.__file__ or ""))


def resolve_scene(scene: str) -> str:
    """The scene script ``scene`` names on this node: a shipped scene's script,
    an existing path, or a file of that base name in the working dir (where
    Ray unpacks a runtime_env ``working_dir``). Raises FileNotFoundError
    saying what was tried."""
    if os.sep not in scene and not scene.endswith(".py"):
        path = os.path.join(shipped_scenes_dir(), scene, f"{scene}_scene.py")
        if not os.path.isfile(path):
            raise FileNotFoundError(
                f"no shipped scene named {scene!r} on node {socket.gethostname()} "
                f"(looked for {path}); is the same remoteenv installed there?"
            )
        return path
    if os.path.isfile(scene):
        return os.path.abspath(scene)
    local = os.path.abspath(os.path.basename(scene))
    if os.path.isfile(local):
        return local
    raise FileNotFoundError(
        f"scene script {scene!r} is not on node {socket.gethostname()} (nor {local}); install the "
        "scene's package on every node, or ship its folder with "
        "RayLauncher(runtime_env={'working_dir': <folder>})"
    )


class SimActor:
    """Starts, watches, restarts and stops one sim process (see the module docstring).

    Args:
        spec: what to start.
        node_ip: the address to bind on; default the node's IP as Ray knows it.
        node_id: the node's id, named in reports; default its Ray node id.
    """

    def __init__(self, spec: SimSpec, node_ip: str | None = None, node_id: str | None = None) -> None:
        if node_ip is None or node_id is None:
            import ray

            node_ip = node_ip or ray.util.get_node_ip_address()
            node_id = node_id or ray.get_runtime_context().get_node_id()
        self.spec = spec
        self.node_ip: str = node_ip
        self.node_id: str = node_id
        self.scene = resolve_scene(spec.scene)
        self.workdir = tempfile.mkdtemp(prefix=f"remoteenv-ray-{spec.instance}-")
        self._workdir_id = identity(self.workdir)
        self._lock = threading.Lock()
        self._sim: SimProcess | None = None
        #: Every child this actor started, by generation (1, 2, ...).
        self._children: dict[int, SimProcess] = {}

    # ------------------------------------------------------------ remote methods

    def start(self, server_secret: bytes, client_public: bytes) -> dict[str, Any]:
        """Start the sim (stopping any previous one) and return where it listens:
        ``{"endpoint", "pid", "node_id", "node_ip", "host", "generation"}``.

        ``server_secret`` is this sim's Z85 CURVE secret key (made by the agent);
        ``client_public`` the one client key the sim admits."""
        with self._lock:
            self._stop_child()
            generation = len(self._children) + 1
            sim = self._spawn(check_key(server_secret, "secret key"), check_key(client_public, "public key"))
            self._sim = self._children[generation] = sim
        try:
            wait_ready(sim, self.spec.startup_timeout, f"{os.path.basename(self.scene)} on node {self.node_ip}")
        except BaseException:
            with self._lock:
                self._stop_child()
            raise
        assert sim.endpoint is not None
        return {
            "endpoint": sim.endpoint,
            "pid": sim.pid,
            "node_id": self.node_id,
            "node_ip": self.node_ip,
            "host": socket.gethostname(),
            "generation": generation,
        }

    def wait_exit(self, generation: int) -> str:
        """Block until child ``generation`` has exited; return why (exit code or
        signal, stderr tail, node)."""
        with self._lock:
            sim = self._children[generation]
        sim.proc.wait()
        return f"{sim.death() or f'pid {sim.pid} exited'} ({self._where()})"

    def death(self) -> str | None:
        """Why the current child is gone, or None while it runs."""
        with self._lock:
            sim = self._sim
        if sim is None:
            return f"no sim process is running ({self._where()})"
        why = sim.death()
        return None if why is None else f"{why} ({self._where()})"

    def kill(self) -> None:
        """SIGKILL the child's process group at once (fault injection, relaunch)."""
        with self._lock:
            if self._sim is not None and self._sim.proc.poll() is None:
                try:
                    os.killpg(self._sim.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass

    def stop(self) -> None:
        """Stop the child (SIGTERM, then SIGKILL after :data:`STOP_GRACE_S`) and
        remove the private dir. The actor can be dropped afterwards."""
        with self._lock:
            self._stop_child()
            if self._workdir_id is not None:  # only the dir made, never what replaced it
                remove_dir(self.workdir, self._workdir_id)

    # ------------------------------------------------------------ internals

    def _where(self) -> str:
        return f"instance {self.spec.instance} on node {self.node_ip} (Ray node id {self.node_id[:12]})"

    def _spawn(self, server_secret: bytes, client_public: bytes) -> SimProcess:
        spec = self.spec
        instance = spec.instance
        names = {
            k: os.path.join(self.workdir, f"sim-{instance}.{k}")
            for k in ("ready.json", "log", "curve_secret", "curve_clients")
        }
        for path in names.values():
            if os.path.exists(path):
                os.unlink(path)
        write_secret_key(names["curve_secret"], server_secret)
        write_public_keys(names["curve_clients"], [client_public])
        address = f"tcp://{self.node_ip}:*"
        cmd = scene_command(
            self.scene,
            address,
            instance=instance,
            worlds=spec.worlds,
            env_kwargs=spec.env_kwargs,
            parent_pid=os.getpid(),
            ready_file=names["ready.json"],
            private_dir=self.workdir,
            seed=spec.seed,
            render_mode=spec.render_mode,
            run=spec.run,
            delay_file=write_sim_delay_file(self.workdir, instance, spec.run.delay_file_text()),
            curve_files=(names["curve_secret"], names["curve_clients"]),
            allow_remote=not is_loopback(address),
            extra_args=spec.extra_args,
        )
        env = dict(os.environ)
        env.setdefault("MUJOCO_GL", "egl")
        with open(names["log"], "ab") as log:
            offset = log.tell()
            proc = subprocess.Popen(
                cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log, env=env, start_new_session=True
            )
        return SimProcess(
            instance=instance, proc=proc, log_path=names["log"], ready_file=names["ready.json"], log_offset=offset
        )

    def _stop_child(self) -> None:
        """Stop the current child, if any (caller holds the lock)."""
        sim, self._sim = self._sim, None
        if sim is None:
            return
        if sim.proc.poll() is None:
            try:
                os.killpg(sim.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                sim.proc.wait(STOP_GRACE_S)
            except subprocess.TimeoutExpired:
                pass
        try:  # the whole group, even if the sim exited and left children
            os.killpg(sim.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        sim.proc.wait()
