"""Launch-info files: drive sims that another process started.

Runs in the agent process. ``python -m remoteenv launch <scene> --out
launch.json`` starts sims and writes a launch-info file;
``OpenAIRemoteEnv.attach("launch.json")`` (or ``gymnasium.make(id,
attach="launch.json")``) and ``RemoteVectorEnv.attach("launch.json")`` drive
them from any other process. Nothing in the file is a secret: the spaces come
from each sim's handshake; when CURVE is on, the file names the sims' public
keys and the path of the client secret key file (mode 0600). ``launch``
writes that key into its private dir, which goes with the sims even when the
command is killed; a relative path is taken from the launch-info file's dir,
and an absolute one that does not exist on this machine falls back to its
file name there (copy the key beside the file to attach from elsewhere).

File format (JSON, ``"format": "remoteenv-launch/1"``)::

    {"format": "remoteenv-launch/1",
     "scene": "/path/to/cartpole_scene.py",   # the scene script the sims run
     "env_id": "remoteenv/CartPole-v0",        # from the handshake
     "host": "machine name",                   # where the sims run
     "launcher_pid": 1234,                     # the launch command's pid
     "worlds_per_instance": 1,
     "render_mode": null | "rgb_array",
     "stepping": {"real_time": false, "real_time_factor": 1.0, "action_delay": 0},
     "instances": [{"instance": 0, "endpoint": "ipc:///tmp/.../sim-0.sock",
                    "pid": 1235, "curve_server_key": null | "<Z85 public key>"}],
     "curve_client_secret_key_file": null | "launch.client.key_secret"}

Any server that speaks :mod:`remoteenv.protocol` can be named in such a file
(``pid`` may be null); that is how an agent drives, say, a real robot bridge.

The file is read as any file a user names (:mod:`remoteenv.wire.files.file_reads`:
never blocking, a regular file of at most :data:`MAX_LAUNCH_INFO_BYTES`, JSON
nested at most 32 deep), and its content is checked before anything is
connected: at most :data:`MAX_INSTANCES` instances of at most
:data:`~remoteenv.wire.codec.frame_limits.MAX_WORLDS` worlds, ``tcp://`` or
``ipc://`` endpoints, well-formed CURVE keys. Anything off is a
:class:`~remoteenv.agent.errors.LaunchError` naming the file and the field.
"""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.connection.zmq_connection import ZmqConnection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.processes import pid_alive
from remoteenv.agent.launch.sim_group import LaunchSpec, SimLayout
from remoteenv.wire.codec.frame_limits import MAX_WORLDS
from remoteenv.wire.files.file_reads import read_json
from remoteenv.wire.files.keys import KeyPair, check_key, load_keypair
from remoteenv.wire.files.safe_writes import write_atomic
from remoteenv.wire.wire_errors import short_repr

FORMAT = "remoteenv-launch/1"
#: Largest launch-info file read (bytes).
MAX_LAUNCH_INFO_BYTES = 1 << 20
#: Most sim instances one launch-info file may name.
MAX_INSTANCES = 1024
#: Longest endpoint taken from a launch-info file (characters).
_MAX_ENDPOINT_CHARS = 1024


@dataclass
class AttachedSim:
    """One sim named in a launch-info file (the attach-side twin of ``SimProcess``)."""

    instance: int
    endpoint: str
    pid: int | None = None
    curve_server_key: bytes | None = None
    #: True when the sim runs on this machine, so its pid can be watched.
    local: bool = True
    restarts: int = 0
    #: The host the launch-info file names, when it is not this machine.
    host: str | None = None

    @property
    def node(self) -> str | None:
        """Where the sim runs: None for this machine, else its host name."""
        return None if self.local else (self.host or "another machine")

    @property
    def pipe(self) -> None:
        """Attached sims have no local pipe to this process."""
        return None

    def death(self) -> str | None:
        """Why the sim's process is gone, or None while it runs (or cannot be watched)."""
        if not self.local or self.pid is None:
            return None
        if not pid_alive(self.pid):
            return (
                f"pid {self.pid} is gone; the sims of a launch-info file live as long as "
                "the launch command that started them"
            )
        return None


@dataclass
class LaunchInfo:
    """The content of a launch-info file (see the module docstring)."""

    scene: str
    instances: list[AttachedSim]
    env_id: str | None = None
    host: str = field(default_factory=socket.gethostname)
    launcher_pid: int | None = None
    worlds_per_instance: int = 1
    render_mode: str | None = None
    real_time: bool = False
    real_time_factor: float = 1.0
    action_delay: int = 0
    curve_client_secret_key_file: str | None = None
    path: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "scene": self.scene,
            "env_id": self.env_id,
            "host": self.host,
            "launcher_pid": self.launcher_pid,
            "worlds_per_instance": self.worlds_per_instance,
            "render_mode": self.render_mode,
            "stepping": {
                "real_time": self.real_time,
                "real_time_factor": self.real_time_factor,
                "action_delay": self.action_delay,
            },
            "instances": [
                {
                    "instance": s.instance,
                    "endpoint": s.endpoint,
                    "pid": s.pid,
                    "curve_server_key": None if s.curve_server_key is None else s.curve_server_key.decode(),
                }
                for s in self.instances
            ],
            "curve_client_secret_key_file": self.curve_client_secret_key_file,
        }

    def client_keypair(self) -> KeyPair | None:
        """The CURVE client key pair the sims admit, or None if CURVE is off."""
        if self.curve_client_secret_key_file is None:
            return None
        path = self.curve_client_secret_key_file
        if self.path is not None and (not os.path.isabs(path) or not os.path.exists(path)):
            path = os.path.join(os.path.dirname(os.path.abspath(self.path)), os.path.basename(path))
        try:
            return load_keypair(path)
        except (OSError, ValueError) as exc:  # ValueError: not a regular file, too large, not a key
            raise RemoteEnvError(
                f"launch-info file {self.path} needs the CURVE client secret key {path}, which cannot "
                f"be read ({short_repr(str(exc), 300)}); copy it (mode 0600) next to the launch-info file",
                kind="launch",
            ) from None


def write_launch_info(path: str | os.PathLike[str], info: LaunchInfo) -> None:
    """Write ``info`` to ``path`` atomically (readers never see half a file),
    never through a symlink planted there or at a temporary name
    (:func:`remoteenv.wire.files.safe_writes.write_atomic`)."""
    path = os.fspath(path)
    write_atomic(path, json.dumps(info.to_json(), indent=2) + "\n", 0o644)
    info.path = path


def read_launch_info(path: str | os.PathLike[str]) -> LaunchInfo:
    """Read a launch-info file; raise :class:`RemoteEnvError` (kind ``"launch"``)
    saying what is wrong with it."""
    path = os.fspath(path)
    try:
        doc = read_json(path, MAX_LAUNCH_INFO_BYTES, what="launch-info file")
    except FileNotFoundError:
        raise RemoteEnvError(
            f"no launch-info file at {path}: start the sims with "
            f"`python -m remoteenv launch <scene> --out {path}` and keep that command running",
            kind="launch",
        ) from None
    except (OSError, ValueError) as exc:  # ValueError: not a regular file, too large, bad or too deep JSON
        raise RemoteEnvError(
            f"cannot read launch-info file {path}: {short_repr(str(exc), 300)}", kind="launch"
        ) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = short_repr(doc.get("format")) if isinstance(doc, dict) else type(doc).__name__
        raise RemoteEnvError(f"{path} is not a launch-info file of format {FORMAT!r} (found {found})", kind="launch")
    try:
        host = str(doc.get("host") or socket.gethostname())
        local = host == socket.gethostname()
        listed = doc["instances"]
        if not isinstance(listed, list) or len(listed) > MAX_INSTANCES:
            raise ValueError(f"'instances' must be a list of at most {MAX_INSTANCES} sims")
        instances = [
            AttachedSim(
                instance=int(s["instance"]),
                endpoint=_endpoint(s["endpoint"]),
                pid=None if s.get("pid") is None else int(s["pid"]),
                curve_server_key=None if not s.get("curve_server_key") else check_key(str(s["curve_server_key"])),
                local=local,
                host=None if local else host,
            )
            for s in listed
        ]
        for key in ("scene", "env_id", "render_mode", "curve_client_secret_key_file"):
            if not isinstance(doc.get(key), (str, type(None))):
                raise ValueError(f"{key!r} must be a string or null, got {short_repr(doc.get(key))}")
        launcher_pid = doc.get("launcher_pid")
        if launcher_pid is not None and (type(launcher_pid) is not int or launcher_pid < 0):
            raise ValueError(f"'launcher_pid' must be a pid or null, got {short_repr(launcher_pid)}")
        stepping = doc.get("stepping") or {}
        info = LaunchInfo(
            scene=str(doc.get("scene") or ""),
            instances=instances,
            env_id=doc.get("env_id"),
            host=host,
            launcher_pid=launcher_pid,
            worlds_per_instance=int(doc.get("worlds_per_instance", 1)),
            render_mode=doc.get("render_mode"),
            real_time=bool(stepping.get("real_time", False)),
            real_time_factor=float(stepping.get("real_time_factor", 1.0)),
            action_delay=int(stepping.get("action_delay", 0)),
            curve_client_secret_key_file=doc.get("curve_client_secret_key_file"),
            path=path,
        )
        if not 1 <= info.worlds_per_instance <= MAX_WORLDS:
            raise ValueError(f"'worlds_per_instance' must be in 1..{MAX_WORLDS}, got {info.worlds_per_instance}")
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise RemoteEnvError(
            f"launch-info file {path} is malformed: {type(exc).__name__}: {short_repr(str(exc), 300)}", kind="launch"
        ) from None
    if not instances:
        raise RemoteEnvError(f"launch-info file {path} names no sim instances", kind="launch")
    return info


def _endpoint(value: Any) -> str:
    """A launch-info file's endpoint, if it is a ``tcp://`` or ``ipc://`` address (ValueError otherwise)."""
    if not (isinstance(value, str) and value.startswith(("tcp://", "ipc://")) and len(value) <= _MAX_ENDPOINT_CHARS):
        raise ValueError(f"endpoint {short_repr(value)} is not a tcp:// or ipc:// address")
    if not value.isprintable():
        raise ValueError(f"endpoint {short_repr(value)} holds control characters")
    return value


class AttachedSims:
    """The sims named by a launch-info file, as a
    :class:`~remoteenv.agent.launch.sim_group.SimGroup` that does not own them: its
    :attr:`layout` is fixed by the file, closing it leaves the sims running
    (the launch command that started them owns them) and it cannot relaunch one.

    Args:
        info: the launch info, or the path of a launch-info file.
        instances: which of its instances to use (default: all, in order).
    """

    #: The launch command owns the sims: envs neither ask them to exit nor relaunch them.
    owns_sims = False

    def __init__(self, info: LaunchInfo | str | os.PathLike[str], instances: Sequence[int] | None = None) -> None:
        if not isinstance(info, LaunchInfo):
            info = read_launch_info(info)
        self.info = info
        by_index = {s.instance: s for s in info.instances}
        wanted = list(by_index) if instances is None else list(instances)
        missing = [i for i in wanted if i not in by_index]
        if missing:
            raise RemoteEnvError(
                f"launch-info file {info.path} has no instance(s) {missing}; it has {sorted(by_index)}",
                kind="launch",
            )
        self.sims = [by_index[i] for i in wanted]
        self.curve_client_keypair = info.client_keypair()
        self.worlds_per_instance = info.worlds_per_instance
        self.num_instances = len(self.sims)
        self._closed = False

    @property
    def layout(self) -> SimLayout:
        """As the file says (the instances chosen, its worlds per instance and stepping)."""
        return SimLayout(
            self.num_instances,
            self.worlds_per_instance,
            self.info.real_time,
            source=f"launch-info file {self.info.path}",
        )

    @property
    def scene(self) -> str:
        return self.info.scene

    @property
    def endpoints(self) -> list[str]:
        return [s.endpoint for s in self.sims]

    @property
    def pids(self) -> list[int | None]:
        return [s.pid for s in self.sims]

    @property
    def timed_steps(self) -> bool:
        """True if the sims run real time or with an action delay."""
        return bool(self.info.real_time or self.info.action_delay)

    def start(self, spec: LaunchSpec) -> None:
        """Attached sims are running already; there is nothing to start."""
        raise RuntimeError(
            f"the sims of launch-info file {self.info.path} are running already; "
            "an env drives them as its layout says, without start()"
        )

    def connect(self, index: int, timeout: float | None) -> SimConnection:
        """A ZeroMQ connection to ``sims[index]`` (attached sims have no local
        pipe), with CURVE when the file names keys."""
        sim, keys = self.sims[index], self.curve_client_keypair
        return ZmqConnection(
            sim.endpoint,
            instance=sim.instance,
            timeout=timeout,
            death_check=sim.death,
            curve_server_key=sim.curve_server_key,
            curve_client_keypair=None if keys is None else (keys.public, keys.secret),
        )

    def restart(self, index: int) -> AttachedSim:
        raise RemoteEnvError(
            f"cannot restart sim instance {self.sims[index].instance}: it was started by the launch "
            f"command (pid {self.info.launcher_pid}), not by this process; restart that command",
            kind="launch",
            instance=self.sims[index].instance,
        )

    def close(self) -> None:
        """Forget the sims (they keep running)."""
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed


__all__ = ["AttachedSim", "AttachedSims", "LaunchInfo", "read_launch_info", "write_launch_info"]
