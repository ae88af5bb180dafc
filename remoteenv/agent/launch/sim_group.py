"""The seam between the env classes and where their sims run.

Runs in the agent process. A :class:`SimGroup` is "a group of sim processes
an env drives": it starts them (or attaches to running ones), names each
one's endpoint and liveness, connects to them, relaunches one, and closes.
:class:`remoteenv.OpenAIRemoteEnv` and :class:`remoteenv.RemoteVectorEnv`
drive any object with this shape (their ``launcher=`` argument) through
:class:`remoteenv.agent.session.sim_session.SimSession`, and never learn which kind it is.

Implementations:

- :class:`remoteenv.agent.launch.launcher.Launcher`: processes on this machine
  (the default); owns its sims.
- :class:`remoteenv.agent.launch.attach.AttachedSims`: the sims of a launch-info
  file; its layout is fixed by the file and it does not own them (closing
  the env leaves them running, and no ``close`` command is sent).
- Placement on a cluster (one actor per sim process, TCP + CURVE) fits the
  same shape: its handles name the node they run on, and their ``death()``
  asks the group rather than this machine's process table.

A group that starts its sims numbers them ``0 .. num_instances - 1`` in
order: ``sims[i].instance == i``; :meth:`SimGroup.restart` and
:meth:`SimGroup.connect` take that index.
"""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.errors import LimitError
from remoteenv.wire.files.keys import KeyPair
from remoteenv.wire.run_options.options import RunOptions

#: Longest JSON text of a launch's env kwargs (characters): they travel on the
#: sim's command line (a fork request below the zygote's control-message limit,
#: or an exec argument below the kernel's 128 KiB per argument).
MAX_ENV_KWARGS_CHARS = 64 * 1024


@dataclass(frozen=True)
class LaunchSpec:
    """What to start: one scene in ``num_instances`` processes of
    ``worlds_per_instance`` MuJoCo worlds each.

    Attributes:
        scene: path of the scene script.
        num_instances: how many sim processes.
        worlds_per_instance: worlds hosted by each process.
        seed: instance ``i``'s RNG seed is ``seed + i * worlds_per_instance``
            (its world ``w``: ``+ w``); None leaves the sims unseeded.
        env_kwargs: keyword arguments for the scene's env class (JSON-able).
        render_mode: passed to the scene's env.
        run: how the sims' worlds run: lock-step or real time, the delays
            (:class:`~remoteenv.wire.run_options.options.RunOptions`, checked
            when it was made, so a bad combination fails before any process starts).
        startup_timeout: seconds to wait for each sim to start (and, by
            default, to answer the handshake).
    """

    scene: str
    num_instances: int = 1
    worlds_per_instance: int = 1
    seed: int | None = None
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    render_mode: str | None = None
    run: RunOptions = field(default_factory=RunOptions)
    startup_timeout: float = 60.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "scene", os.fspath(self.scene))
        object.__setattr__(self, "env_kwargs", dict(self.env_kwargs))
        if self.num_instances < 1 or self.worlds_per_instance < 1:
            raise ValueError("num_instances and worlds_per_instance must be >= 1")
        try:
            size = len(json.dumps(self.env_kwargs))
        except TypeError as exc:
            raise TypeError(f"env kwargs must be JSON-serializable to reach the scene: {exc}") from None
        if size > MAX_ENV_KWARGS_CHARS:
            raise LimitError(
                f"env kwargs take {size} characters as JSON, more than the {MAX_ENV_KWARGS_CHARS} a sim's "
                "command line carries: pass large data as a file path the scene reads instead"
            )

    def layout(self, source: str) -> SimLayout:
        """The layout of the sims this spec starts; ``source`` names who started them, for messages."""
        return SimLayout(self.num_instances, self.worlds_per_instance, self.run.real_time, source=source)

    def instance_seed(self, instance: int) -> int | None:
        """The seed of sim ``instance`` (of its world 0), or None."""
        return None if self.seed is None else self.seed + instance * self.worlds_per_instance


@dataclass(frozen=True)
class SimLayout:
    """How a group that is already running is laid out, for an env to check
    its own arguments against before it drives it.

    Attributes:
        num_instances: sim processes in the group.
        worlds_per_instance: worlds each one hosts.
        real_time: whether the sims run on a paced clock.
        source: what fixed the layout, for messages (e.g. "launch-info file x.json").
    """

    num_instances: int
    worlds_per_instance: int
    real_time: bool
    source: str

    @property
    def num_worlds(self) -> int:
        return self.num_instances * self.worlds_per_instance


@runtime_checkable
class SimHandle(Protocol):
    """One sim process of a group."""

    @property
    def instance(self) -> int:
        """The sim's instance number (its ``--instance``; named in errors)."""

    @property
    def endpoint(self) -> str | None:
        """Its bound ZeroMQ endpoint (None until it reported one)."""

    @property
    def pid(self) -> int | None:
        """Its process id on its node, if known."""

    @property
    def curve_server_key(self) -> bytes | None:
        """Its public Z85 CURVE key when CURVE is on, else None."""

    @property
    def pipe(self) -> socket.socket | None:
        """This process's end of a local pipe to the sim, if the group made one."""

    @property
    def node(self) -> str | None:
        """Where the sim runs: None for this machine, else a host or node name."""

    def death(self) -> str | None:
        """Why the sim is gone (exit status, last stderr lines...), or None while
        it runs or when nobody can tell. Must return within milliseconds: a
        waiting call asks every 0.1 s."""


@runtime_checkable
class SimGroup(Protocol):
    """A group of sim processes an env drives (see the module docstring)."""

    @property
    def sims(self) -> Sequence[SimHandle]:
        """The handles, in instance order; empty before :meth:`start`."""

    @property
    def curve_client_keypair(self) -> KeyPair | None:
        """The CURVE client key pair the sims admit, or None when CURVE is off."""

    @property
    def owns_sims(self) -> bool:
        """True if closing the group stops the sims (and an env may ask them to
        exit and may relaunch them); False for sims someone else started."""

    @property
    def layout(self) -> SimLayout | None:
        """The layout when it is already fixed (a running or attached group);
        None while :meth:`start` is still to decide it."""

    @property
    def closed(self) -> bool: ...

    def start(self, spec: LaunchSpec) -> None:
        """Start the sims ``spec`` describes and return once each one serves
        its endpoint; raise :class:`remoteenv.LaunchError` naming the instance
        that failed (after stopping the others)."""

    def connect(self, index: int, timeout: float | None) -> SimConnection:
        """A new connection to ``sims[index]``; ``timeout`` is its default
        reply timeout in seconds (None: wait forever, still noticing death)."""

    def restart(self, index: int) -> SimHandle:
        """Stop ``sims[index]`` if it still runs and start it afresh; return
        the new handle. Raises :class:`remoteenv.LaunchError` if the group
        cannot (e.g. it does not own its sims)."""

    def close(self) -> None:
        """Let go of the sims (stopping them if the group owns them); idempotent."""


__all__ = ["LaunchSpec", "SimGroup", "SimHandle", "SimLayout"]
