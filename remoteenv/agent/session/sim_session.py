"""One env's sims from start to close: the session both env classes share.

Runs in the agent process. A :class:`SimSession` takes a
:class:`~remoteenv.agent.launch.sim_group.SimGroup` (launching or attached), starts
it unless its layout is fixed, connects to every sim, does the handshakes
(all in flight at once) and parses them into
:class:`~remoteenv.wire.messages.handshake.Handshake`, keeps the connections and the
restart budget, relaunches one sim when asked and closes everything. Every
reply that comes through :meth:`SimSession.request` is checked against the
handshake first (:mod:`~remoteenv.agent.connection.reply_checks`); the vector env's own
fan-out checks its replies with the same :attr:`SimSession.checks`.
:func:`choose_group` turns an env's ``launcher=``/``attach=`` arguments into
the group, and :func:`open_session` opens a session over it from the env's
constructor arguments.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import zmq

from remoteenv.agent.connection.connect import SimConnection
from remoteenv.agent.connection.reply_checks import ReplyChecks
from remoteenv.agent.connection.take_over import retry_taking_over
from remoteenv.agent.errors import BatchTooLargeError, RemoteEnvError
from remoteenv.agent.launch.attach import AttachedSims
from remoteenv.agent.launch.launcher import Launcher
from remoteenv.agent.launch.restart import RestartBudget
from remoteenv.agent.launch.sim_group import LaunchSpec, SimGroup
from remoteenv.agent.session.scene_signature import check_scene_kwargs
from remoteenv.wire.messages.handshake import BatchTooLarge, Handshake, handshake_request, parse_handshake
from remoteenv.wire.wire_errors import ProtocolError

#: Seconds to wait for a sim to acknowledge ``close`` (unless ``call_timeouts``
#: says otherwise) before its group stops it anyway.
CLOSE_REPLY_S = 1.0

#: Commands whose timeout ``call_timeouts`` sets under another name.
_TIMEOUT_NAMES = {"reset_batch": "reset", "step_batch": "step"}


def choose_group(
    launcher: SimGroup | None,
    attach: Any,
    *,
    attach_instances: Sequence[int] | None = None,
    transport: str = "pipe",
    bind_host: str | None = None,
    curve: bool | None = None,
) -> SimGroup:
    """The group an env drives: ``attach`` (a launch-info path, or an
    :class:`~remoteenv.agent.launch.attach.AttachedSims`; ``attach_instances`` picks
    a path's instances), else ``launcher``, else a local
    :class:`~remoteenv.agent.launch.launcher.Launcher` with the given connection options."""
    if attach is not None and launcher is not None:
        raise ValueError("give launcher= or attach=, not both: attach= names sims that are running already")
    if attach is not None:
        return attach if isinstance(attach, AttachedSims) else AttachedSims(attach, attach_instances)
    if launcher is not None:
        return launcher
    return Launcher(transport=transport, bind_host=bind_host, curve=curve)


class SimSession:
    """The sims of one env: start or attach, connect, handshake, relaunch, close.

    Args:
        group: the sims' group. It is started with ``spec`` unless its
            :attr:`~remoteenv.agent.launch.sim_group.SimGroup.layout` is fixed already.
            The session closes it.
        spec: what to start (None for a group whose layout is fixed).
        timeout: default seconds to wait for any one reply (None: forever, a
            dead sim is still reported within ~0.1 s).
        call_timeouts: per-command timeouts overriding ``timeout``
            (``handshake``, ``reset``, ``step``, ``render``, ``close``; the
            batch commands count as ``reset`` and ``step``). The handshake's
            default is ``startup_timeout``, close's :data:`CLOSE_REPLY_S`.
        startup_timeout: default handshake timeout in seconds.
        restart_on_failure, max_restarts: see :class:`~remoteenv.agent.launch.restart.RestartBudget`.
        label: how messages name the env, e.g. ``"OpenAIRemoteEnv (cartpole_scene.py)"``.
        measure_world_cost: ask the first sim's handshake to measure what one
            world's tick costs (``Handshake.world_cost_s``; a vector env's default layout reads it).
        probe: the session is opened only to learn the scene and closed after
            its handshake: its first sim may measure on its own world (the
            handshake's ``"probe"``).
    """

    def __init__(
        self,
        group: SimGroup,
        spec: LaunchSpec | None,
        *,
        timeout: float | None = 60.0,
        call_timeouts: Mapping[str, float | None] | None = None,
        startup_timeout: float = 60.0,
        restart_on_failure: bool = False,
        max_restarts: int = 3,
        label: str = "env",
        measure_world_cost: bool = False,
        probe: bool = False,
    ) -> None:
        self.restarts = RestartBudget(restart_on_failure, max_restarts)
        self.measure_world_cost = measure_world_cost
        self.probe = probe
        if restart_on_failure and not group.owns_sims:
            raise ValueError(
                "restart_on_failure needs sims this env launched; attached sims belong to the launch command"
            )
        if spec is None and group.layout is None:
            raise ValueError(f"{label}: a group that is not started yet needs a LaunchSpec")
        self.group = group
        self.spec = spec
        self.timeout = timeout
        self.call_timeouts: dict[str, float | None] = dict(call_timeouts or {})
        self.startup_timeout = startup_timeout
        self.label = label
        #: One connection per sim, in the group's order (empty once closed).
        self.conns: list[SimConnection] = []
        #: The latest handshake of each sim, in the group's order.
        self.handshakes: list[Handshake] = []
        #: The checks of every reply (against the first sim's handshake, whose spaces the env has).
        self.checks: ReplyChecks | None = None
        self.closed = False

    # ------------------------------------------------------------ lifecycle

    def open(self) -> None:
        """Start the group (unless its layout is fixed), connect and handshake
        every sim. On any failure everything is closed before the error propagates."""
        try:
            if self.group.layout is None:
                assert self.spec is not None
                names = [*self.spec.env_kwargs, *(["render_mode"] if self.spec.render_mode is not None else [])]
                check_scene_kwargs(self.spec.scene, names)
                self.group.start(self.spec)
            for index in range(len(self.group.sims)):
                self.conns.append(self.group.connect(index, self.timeout))
            timeout = self.timeout_for("handshake")
            seqs = [
                conn.send(
                    "handshake",
                    **handshake_request(world_cost=self.measure_world_cost and index == 0, probe=self.probe),
                )
                for index, conn in enumerate(self.conns)
            ]
            self.handshakes = [
                self._parse(conn, conn.receive(seq, timeout, what="'handshake'")) for conn, seq in zip(self.conns, seqs)
            ]
            self.checks = ReplyChecks(self.handshakes[0].observation_space)
        except BaseException:
            self.close()
            raise

    def relaunch(self, index: int, err: RemoteEnvError) -> int:
        """Relaunch sim ``index`` after ``err``: spend a restart per attempt until
        one comes up and answers its handshake. Returns the restarts spent so far;
        raises (naming ``max_restarts``) once the budget is spent."""
        while True:
            count = self.restarts.spend(err)
            self.conns[index].close()
            try:
                self.group.restart(index)
                self.conns[index] = conn = self.group.connect(index, self.timeout)
                reply = conn.request("handshake", timeout=self.timeout_for("handshake"), **handshake_request())
                self.handshakes[index] = self._parse(conn, reply)
                return count
            except RemoteEnvError as again:
                err = again

    def close(self) -> None:
        """Ask the sims to exit (only those the group owns), close the
        connections, close the group. Idempotent; never raises for a sim that
        is gone already."""
        if self.closed:
            return
        self.closed = True
        conns, self.conns = self.conns, []
        pending = []
        if self.group.owns_sims:  # attached sims outlive the env
            for conn in conns:
                try:
                    pending.append((conn, conn.send("close")))
                except (zmq.ZMQError, RemoteEnvError):
                    pass
        timeout = self.timeout_for("close")
        for conn, seq in pending:
            try:
                conn.receive(seq, timeout, what="'close'")
            except RemoteEnvError:
                pass
        for conn in conns:
            conn.close()
        self.group.close()

    # ------------------------------------------------------------ requests

    @property
    def handshake(self) -> Handshake:
        """The handshake of the first sim (all sims of a group serve one scene)."""
        return self.handshakes[0]

    @property
    def pids(self) -> list[int | None]:
        """Process ids of the sims (empty once closed)."""
        if self.closed or self.group.closed:
            return []
        return [sim.pid for sim in self.group.sims]

    @property
    def local_sims(self) -> int:
        """How many of the sims this session's group started on this machine (0 for attached sims)."""
        if not self.group.owns_sims:
            return 0
        return sum(1 for sim in self.group.sims if sim.node is None)

    def timeout_for(self, cmd: str) -> float | None:
        """Seconds to wait for the reply to ``cmd`` (see ``call_timeouts``)."""
        timeouts = self.call_timeouts
        if cmd in timeouts:
            return timeouts[cmd]
        name = _TIMEOUT_NAMES.get(cmd, cmd)
        if name in timeouts:
            return timeouts[name]
        if cmd == "handshake":
            return self.startup_timeout
        if cmd == "close":
            return CLOSE_REPLY_S
        return self.timeout

    def connection(self, index: int, cmd: str) -> SimConnection:
        """The connection to sim ``index``; a :class:`remoteenv.StateError` once closed."""
        if self.closed:
            raise RemoteEnvError(f"{cmd} on a closed {self.label}; create a new env", kind="state")
        return self.conns[index]

    def request(self, index: int, cmd: str, **args: Any) -> dict[str, Any]:
        """Send ``cmd`` to sim ``index`` and wait for its reply (timeout per
        :meth:`timeout_for`), checked against the handshake
        (:class:`~remoteenv.agent.errors.RemoteProtocolError` if it is off)."""
        conn = self.connection(index, cmd)
        timeout = self.timeout_for(cmd)
        if cmd in ("reset", "reset_batch"):  # may follow a previous driver's close by a moment
            reply = retry_taking_over(lambda: conn.request(cmd, timeout=timeout, **args))
        else:
            reply = conn.request(cmd, timeout=timeout, **args)
        checks = self.checks
        if checks is None:
            return reply
        if cmd == "reset":
            return checks.reset(conn, reply)
        if cmd == "step":
            return checks.step(conn, reply)
        if cmd == "render":
            return checks.frame(conn, reply)
        if cmd in ("get_attr", "call"):
            return checks.attribute(conn, cmd, reply)
        if cmd == "reset_batch":
            return checks.batch(conn, cmd, reply, len(args["worlds"]))
        if cmd == "step_batch" and not args.get("shared"):
            return checks.batch(conn, cmd, reply, len(args["ops"]))
        return reply

    def _parse(self, conn: SimConnection, reply: dict[str, Any]) -> Handshake:
        try:
            return parse_handshake(reply)
        except BatchTooLarge as exc:
            err = BatchTooLargeError(
                f"sim instance {conn.instance} at {conn.endpoint} gave {self.label} a handshake it cannot use: {exc}",
                instance=conn.instance,
            )
            err.worlds_that_fit = exc.worlds_that_fit
            raise err from None
        except ProtocolError as exc:
            raise RemoteEnvError(
                f"sim instance {conn.instance} at {conn.endpoint} gave {self.label} a handshake it cannot use: {exc}",
                kind="protocol",
                instance=conn.instance,
            ) from None


def open_session(
    group: SimGroup,
    label: str,
    scene: str,
    num_instances: int,
    worlds_per_instance: int,
    *,
    timeout: float | None,
    call_timeouts: Mapping[str, float | None] | None,
    startup_timeout: float,
    restart_on_failure: bool,
    max_restarts: int,
    measure_world_cost: bool = False,
    probe: bool = False,
    **launch: Any,
) -> SimSession:
    """An open session over ``group``, as an env's constructor makes it.

    A group whose layout is fixed already is driven as it is; any other is
    started with a :class:`~remoteenv.agent.launch.sim_group.LaunchSpec` of
    ``scene`` in ``num_instances`` processes of ``worlds_per_instance`` worlds
    each, with ``startup_timeout`` and the ``launch`` options (the spec's other
    fields: ``seed``, ``env_kwargs``, ``render_mode``, ``real_time``,
    ``real_time_factor``, ``real_time_mode``, ``action_delay``, ``obs_delay``, ``link_delay``).
    ``label`` and the other arguments (``measure_world_cost`` and ``probe`` too) are :class:`SimSession`'s.
    """
    spec = (
        None
        if group.layout is not None
        else LaunchSpec(scene, num_instances, worlds_per_instance, startup_timeout=startup_timeout, **launch)
    )
    session = SimSession(
        group,
        spec,
        timeout=timeout,
        call_timeouts=call_timeouts,
        startup_timeout=startup_timeout,
        restart_on_failure=restart_on_failure,
        max_restarts=max_restarts,
        label=label,
        measure_world_cost=measure_world_cost,
        probe=probe,
    )
    session.open()
    return session


def scene_label(cls_name: str, scene: str | os.PathLike[str]) -> str:
    """How messages name an env: ``"OpenAIRemoteEnv (cartpole_scene.py)"``."""
    return f"{cls_name} ({os.path.basename(os.fspath(scene))})"


__all__ = ["CLOSE_REPLY_S", "SimSession", "choose_group", "open_session", "scene_label"]
