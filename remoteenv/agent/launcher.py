"""Launcher: starts sim processes, watches them and stops them.

Runs in the agent process. Each sim is ``python <scene script> --address ...``
in a session (process group) of its own, bound to a collision-free address:
an ipc socket in a private temp dir, or tcp on 127.0.0.1 with a port the OS
assigns. The launcher waits until each sim reports its bound endpoint (never a
fixed sleep), and stops them on :meth:`close`, on interpreter exit or when it
is garbage collected: SIGTERM to the process group, then SIGKILL, then the
private dir (socket files, logs) is removed. Each sim also watches its parent
and exits if the agent dies.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import weakref
from dataclasses import dataclass, field
from typing import Any, Sequence

from remoteenv.wire.addresses import ipc_address, ipc_path, is_loopback, tcp_loopback_address, zmq_transport
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire.keys import KeyPair, generate_keypair, write_public_keys, write_secret_key

_STDERR_TAIL_LINES = 20


def pid_alive(pid: int) -> bool:
    """True while process ``pid`` exists and is not a zombie (Linux /proc; elsewhere signal 0)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
    except OSError:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True


@dataclass
class SimProcess:
    """One launched sim process."""

    instance: int
    proc: subprocess.Popen
    log_path: str
    ready_file: str
    endpoint: str | None = None
    restarts: int = 0
    #: The sim's public Z85 CURVE key when CURVE is on, else None.
    curve_server_key: bytes | None = None
    #: Where this process's stderr starts in the log (a restart appends to it).
    log_offset: int = 0
    #: The launcher's end of the local pipe (see :mod:`remoteenv.protocol`), or None.
    pipe: socket.socket | None = None

    def close_pipe(self) -> None:
        if self.pipe is not None:
            self.pipe.close()
            self.pipe = None

    @property
    def pid(self) -> int:
        return self.proc.pid

    def stderr_tail(self, lines: int = _STDERR_TAIL_LINES) -> str:
        """The last ``lines`` lines the process wrote to stderr."""
        try:
            with open(self.log_path, "rb") as f:
                f.seek(0, os.SEEK_END)
                size = f.tell()
                f.seek(max(self.log_offset, size - 16384))
                text = f.read().decode("utf-8", "replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def death(self) -> str | None:
        """Why the process is gone (exit code or signal, stderr tail), or None if it runs."""
        code = self.proc.poll()
        if code is None:
            return None
        if code < 0:
            try:
                how = f"killed by signal {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exited with code {code}"
        tail = self.stderr_tail()
        text = f"pid {self.proc.pid} {how}"
        if tail:
            text += f"; last lines of its stderr:\n{tail}"
        return text


@dataclass
class _State:
    """What the finalizer needs; holds no reference to the Launcher."""

    workdir: str
    sims: list[SimProcess] = field(default_factory=list)


def _stop_all(state: _State, grace: float = 2.0) -> None:
    for sim in state.sims:
        if sim.proc.poll() is None:
            try:
                os.killpg(sim.proc.pid, signal.SIGTERM)
            except (ProcessLookupError, PermissionError):
                pass
    deadline = time.monotonic() + grace
    for sim in state.sims:
        try:
            sim.proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            try:
                os.killpg(sim.proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            sim.proc.wait()
        # Reap the group even if the sim exited by itself but left children.
        try:
            os.killpg(sim.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        sim.close_pipe()
    shutil.rmtree(state.workdir, ignore_errors=True)


class Launcher:
    """Starts ``num_instances`` sim processes of one scene.

    Args:
        scene: path of the scene script.
        num_instances: how many sim processes.
        seed: RNG seed; instance ``i`` gets ``seed + i * worlds_per_instance``.
        worlds_per_instance: MuJoCo worlds hosted by each process.
        env_kwargs: keyword arguments for the scene's env class (JSON-able).
        render_mode: passed to the scene's env.
        transport: ``"ipc"`` (default): each sim binds an ipc endpoint in the
            private dir; ``"tcp"``: 127.0.0.1 with an OS-assigned port;
            ``"pipe"``: ipc, and each sim also gets one end of a Unix socketpair
            (the local pipe, :attr:`SimProcess.pipe`), the fastest way for this
            process to talk to it.
        startup_timeout: seconds to wait for a sim to report ready.
        real_time, real_time_factor, action_delay: stepping mode of the sims.
        extra_args: more command-line arguments for the scene script.
        bind_host: bind tcp on this interface (OS-assigned port) instead of the
            default. Anything but loopback turns CURVE on and cannot turn it off.
        curve: encrypt and authenticate with ZMQ CURVE. Each sim gets a fresh
            server key pair (secret in the private dir, mode 0600); this
            launcher holds the one client key pair the sims admit
            (:attr:`curve_client_keypair`). Default: on iff ``bind_host`` is
            beyond loopback.
    """

    def __init__(
        self,
        scene: str | os.PathLike[str],
        num_instances: int = 1,
        *,
        seed: int | None = None,
        worlds_per_instance: int = 1,
        env_kwargs: dict[str, Any] | None = None,
        render_mode: str | None = None,
        transport: str = "ipc",
        startup_timeout: float = 60.0,
        real_time: bool = False,
        real_time_factor: float = 1.0,
        action_delay: int = 0,
        extra_args: Sequence[str] = (),
        bind_host: str | None = None,
        curve: bool | None = None,
    ) -> None:
        self.scene = os.path.abspath(os.fspath(scene))
        if not os.path.isfile(self.scene):
            raise FileNotFoundError(f"scene script {self.scene!r} does not exist")
        if num_instances < 1 or worlds_per_instance < 1:
            raise ValueError("num_instances and worlds_per_instance must be >= 1")
        self.num_instances = num_instances
        self.seed = seed
        self.worlds_per_instance = worlds_per_instance
        self.env_kwargs = dict(env_kwargs or {})
        self.render_mode = render_mode
        self.transport = zmq_transport(transport)  # raises for an unknown transport
        self.pipe = transport == "pipe"
        self.startup_timeout = startup_timeout
        self.real_time = real_time
        self.real_time_factor = real_time_factor
        self.action_delay = action_delay
        self.extra_args = list(extra_args)
        self.bind_address: str | None = None
        if bind_host is not None:
            self.transport = "tcp"
            self.bind_address = f"tcp://{bind_host}:*"
        remote = self.bind_address is not None and not is_loopback(self.bind_address)
        if remote and curve is False:
            raise ValueError(
                f"binding {bind_host!r} (beyond loopback) requires CURVE; drop curve=False"
            )
        self.remote = remote
        #: The client key pair the sims admit, when CURVE is on.
        self.curve_client_keypair: KeyPair | None = (
            generate_keypair() if (remote or bool(curve)) else None
        )
        try:
            json.dumps(self.env_kwargs)
        except TypeError as exc:
            raise TypeError(f"env kwargs must be JSON-serializable to reach the scene: {exc}") from None
        self._state = _State(workdir=tempfile.mkdtemp(prefix="remoteenv-"))
        self._finalizer = weakref.finalize(self, _stop_all, self._state)
        try:
            for i in range(num_instances):
                self._state.sims.append(self._spawn(i))
            for sim in self._state.sims:
                self._wait_ready(sim)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ public

    @property
    def workdir(self) -> str:
        """The private temp dir holding socket files and logs."""
        return self._state.workdir

    @property
    def sims(self) -> list[SimProcess]:
        return self._state.sims

    @property
    def endpoints(self) -> list[str]:
        return [s.endpoint for s in self._state.sims if s.endpoint is not None]

    @property
    def pids(self) -> list[int]:
        return [s.pid for s in self._state.sims]

    def instance_seed(self, instance: int) -> int | None:
        return None if self.seed is None else self.seed + instance * self.worlds_per_instance

    def restart(self, instance: int) -> SimProcess:
        """Kill instance ``instance`` if it still runs and launch it afresh."""
        old = self._state.sims[instance]
        if old.proc.poll() is None:
            try:
                os.killpg(old.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        old.proc.wait()
        old.close_pipe()
        new = self._spawn(instance)
        new.restarts = old.restarts + 1
        self._state.sims[instance] = new
        self._wait_ready(new)
        return new

    def close(self) -> None:
        """Stop every sim (SIGTERM, then SIGKILL after 2 s) and remove the private dir."""
        self._finalizer()

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    def __enter__(self) -> "Launcher":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------ internals

    def _spawn(self, instance: int) -> SimProcess:
        workdir = self._state.workdir
        if self.bind_address is not None:
            address = self.bind_address
        elif self.transport == "ipc":
            address = ipc_address(workdir, instance)
        else:
            address = tcp_loopback_address()
        ready_file = os.path.join(workdir, f"sim-{instance}.ready.json")
        log_path = os.path.join(workdir, f"sim-{instance}.log")
        for path in (ready_file, ipc_path(address)):
            if path and os.path.exists(path):
                os.unlink(path)
        cmd = [
            sys.executable, self.scene,
            "--address", address,
            "--instance", str(instance),
            "--worlds", str(self.worlds_per_instance),
            "--env-kwargs", json.dumps(self.env_kwargs),
            "--parent-pid", str(os.getpid()),
            "--ready-file", ready_file,
            "--private-dir", workdir,
        ]
        server_key = None
        if self.curve_client_keypair is not None:
            server = generate_keypair()
            server_key = server.public
            secret_file = os.path.join(workdir, f"sim-{instance}.curve_secret")
            clients_file = os.path.join(workdir, f"sim-{instance}.curve_clients")
            for path in (secret_file, clients_file):
                if os.path.exists(path):
                    os.unlink(path)
            write_secret_key(secret_file, server.secret)
            write_public_keys(clients_file, [self.curve_client_keypair.public])
            cmd += ["--curve-secret-key-file", secret_file, "--curve-client-keys-file", clients_file]
            if self.remote:
                cmd += ["--allow-remote"]
        seed = self.instance_seed(instance)
        if seed is not None:
            cmd += ["--seed", str(seed)]
        if self.render_mode is not None:
            cmd += ["--render-mode", self.render_mode]
        if self.real_time:
            cmd += ["--real-time", "--real-time-factor", repr(float(self.real_time_factor))]
        if self.action_delay:
            cmd += ["--action-delay", str(int(self.action_delay))]
        cmd += self.extra_args
        env = dict(os.environ)
        if self.render_mode != "human":
            env.setdefault("MUJOCO_GL", "egl")
        ours = theirs = None
        if self.pipe:
            ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            cmd += ["--pipe-fd", str(theirs.fileno())]
        try:
            with open(log_path, "ab") as log:
                log_offset = log.tell()
                proc = subprocess.Popen(
                    cmd, stdin=subprocess.DEVNULL, stderr=log, env=env, start_new_session=True,
                    pass_fds=() if theirs is None else (theirs.fileno(),),
                )
        except BaseException:
            if ours is not None:
                ours.close()
            raise
        finally:
            if theirs is not None:
                theirs.close()
        return SimProcess(instance=instance, proc=proc, log_path=log_path, ready_file=ready_file,
                          curve_server_key=server_key, log_offset=log_offset, pipe=ours)

    def _wait_ready(self, sim: SimProcess) -> None:
        deadline = time.monotonic() + self.startup_timeout
        delay = 0.002
        while True:
            try:
                with open(sim.ready_file) as f:
                    info = json.load(f)
                sim.endpoint = str(info["endpoint"]).replace("tcp://0.0.0.0:", "tcp://127.0.0.1:")
                return
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                pass
            why = sim.death()
            if why is not None:
                raise RemoteEnvError(
                    f"sim instance {sim.instance} of {os.path.basename(self.scene)} failed to "
                    f"start: {why}",
                    kind="launch",
                    instance=sim.instance,
                )
            if time.monotonic() > deadline:
                raise RemoteEnvError(
                    f"sim instance {sim.instance} (pid {sim.pid}) of {os.path.basename(self.scene)} "
                    f"did not report ready within {self.startup_timeout:g} s; raise "
                    f"startup_timeout= if the machine is busy. Its stderr so far:\n{sim.stderr_tail()}",
                    kind="launch",
                    instance=sim.instance,
                )
            time.sleep(delay)
            delay = min(delay * 1.5, 0.05)
