"""OpenAIRemoteEnv: a Gymnasium env whose world lives in a sim process.

Runs in the agent process. ``reset``/``step``/``render`` become requests to
the sim (see :mod:`remoteenv.protocol`); spaces and metadata come from the
sim's handshake, so they are declared once, in the scene. Where the sim runs
is a :class:`~remoteenv.agent.launch.sim_group.SimGroup` (``launcher=``/``attach=``);
its lifecycle (start or attach, handshake, restarts, close) is the
:class:`~remoteenv.agent.session.sim_session.SimSession` this env shares with
:class:`remoteenv.RemoteVectorEnv`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.restart import restarted_info
from remoteenv.agent.launch.sim_group import SimGroup
from remoteenv.agent.session.forwarding import SceneAttributes, SceneReach
from remoteenv.agent.session.latency_stats import LatencyStats
from remoteenv.agent.session.pausing import Pausable, Pauser
from remoteenv.agent.session.pickling import RebuildOnUnpickle, remember_init_args
from remoteenv.agent.session.session_attributes import SessionAttributes
from remoteenv.agent.session.sim_session import choose_group, open_session, scene_label
from remoteenv.wire.codec.scalar_types import restore_scalars
from remoteenv.wire.delays.channel_rules import NEWEST
from remoteenv.wire.delays.delay_specs import DelaySpec
from remoteenv.wire.messages.action_rules import check_action
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import ELASTIC

__all__ = ["OpenAIRemoteEnv", "check_action"]


class OpenAIRemoteEnv(SessionAttributes, SceneAttributes, Pausable, RebuildOnUnpickle, gym.Env):
    """A Gymnasium env served by a sim process that this env launches.

    Usually created with ``gymnasium.make("remoteenv/CartPole-v0", ...)``;
    keyword arguments that are not listed below are passed on to the scene's
    env class in the sim process (they must be JSON-serializable).

    Args:
        scene: path of the scene script to launch.
        render_mode: ``"rgb_array"`` renders offscreen in the sim process.
        real_time: run the sim on a paced wall clock (see docs/real-time.md).
        real_time_factor: simulated seconds per wall-clock second.
        real_time_mode: with ``real_time``, the regime
            (:mod:`remoteenv.wire.run_options.real_time_modes`): elastic (the
            default: an action takes effect at the next physics substep) or
            fixed step (rtgym's: at the next control-tick boundary).
        action_delay: lock-step; an action takes effect this many ticks later:
            an int, or a :mod:`remoteenv.delays` spec in ticks (e.g.
            ``Uniform(0, 3)``), drawn per step from a stream seeded by
            ``reset(seed=...)`` (see ``docs/delays.md``).
        obs_delay: lock-step; the step returns the newest observation that has
            arrived, observations arriving this many ticks late (int or spec).
        link_delay: real time; an emulated network's extra delay per action,
            in wall seconds (a number, or a spec with ``unit="s"`` for jitter).
        action_delivery: lock-step, with a delay: ``"newest"`` (default: the
            newest arrived action acts) or ``"in_order"`` (an action also waits
            for every older one, TCP-like); see ``docs/delays.md``.
        obs_delivery: the same choice for observations.
        delayed_rewards: lock-step, with a delay: reward, ``terminated`` and the
            scene's info travel with the delayed observation (the physics
            freezes at termination until its observation arrives).
        seed: seed of the sim's RNG until the first ``reset(seed=...)``.
        transport: how this env talks to its sim: ``"pipe"`` (default: a Unix
            socketpair the launcher hands the sim; the fastest), or ZeroMQ over
            ``"ipc"`` or ``"tcp"`` (loopback, OS-assigned port). The sim binds
            an ipc (or, with ``"tcp"``, tcp) ZeroMQ endpoint in every case.
        timeout: seconds to wait for any one reply before
            :class:`remoteenv.RemoteEnvTimeout` (a dead sim is reported within
            ~0.1 s regardless).
        startup_timeout: seconds to wait for the sim to start.
        call_timeouts: per-command timeouts that override ``timeout``, e.g.
            ``{"reset": 120.0, "step": 5.0}`` (commands: handshake, reset,
            step, render, close).
        restart_on_failure: when the sim process dies or times out, launch a
            fresh one. A failed ``step`` then returns the last observation
            with ``truncated=True``, reward 0.0 and
            ``info["remoteenv_restarted"] = True``; a failed ``reset`` is
            retried on the new sim and its info says the same.
        max_restarts: restarts allowed over this env's life; the next failure
            is raised as :class:`remoteenv.RemoteEnvError`.
        bind_host: have the sim bind tcp on this interface; beyond loopback
            this turns on CURVE (see :class:`remoteenv.Launcher`).
        curve: encrypt and authenticate with ZMQ CURVE even on loopback.
        launcher: the :class:`~remoteenv.agent.launch.sim_group.SimGroup` that starts
            the sim (default: a local :class:`remoteenv.Launcher` with
            ``transport``, ``bind_host`` and ``curve``, which are ignored when
            this is given). A group whose layout is fixed already (e.g.
            :class:`~remoteenv.agent.launch.attach.AttachedSims`) is driven as it is;
            it must hold one sim. The env closes the group when it closes.
        attach: instead of launching a sim, drive instance 0 of the sims named
            by this launch-info file (see :mod:`remoteenv.agent.launch.attach`, and
            :meth:`attach` for other instances). The launch options above are
            then ignored, and ``close`` leaves the sim running.

    Real time: :meth:`pause`, :meth:`resume` and ``with env.unwrapped.paused():``
    stop the sim's clock between steps (no-ops in lock-step; see
    :mod:`remoteenv.agent.session.pausing`).

    The scene's own attributes and methods are reachable too: :meth:`call`,
    :meth:`get_scene_attr`, :meth:`set_scene_attr`, and ``get_wrapper_attr`` /
    ``set_wrapper_attr`` (what Gymnasium's ``SyncVectorEnv.call`` uses) fall
    through to the scene for names this class does not have
    (:class:`~remoteenv.agent.session.forwarding.SceneAttributes`).

    Pickling or ``copy.deepcopy`` builds a new env from the same constructor
    arguments, with a fresh sim (see :mod:`remoteenv.agent.session.pickling`).

    Attributes:
        run_options: the run options the arguments above make
            (:class:`~remoteenv.wire.run_options.options.RunOptions`: real time, its
            factor and regime, the delays and their rules), checked once and sent
            whole to the sims (attached sims run what they were launched with).
        latency_stats: :class:`remoteenv.agent.session.latency_stats.LatencyStats` of every step so
            far: action latency (mean/p50/p99/max, seconds and ticks), wall
            round trip, late actions, pacing overruns. With ``real_time`` or
            ``action_delay`` each step's info also carries the timing keys
            (see docs/real-time.md) plus ``wall_round_trip_s``, the wall
            seconds from sending the step to receiving its reply.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "human"], "render_fps": None}

    @remember_init_args
    def __init__(
        self,
        scene: str | os.PathLike[str],
        render_mode: str | None = None,
        *,
        real_time: bool = False,
        real_time_factor: float = 1.0,
        real_time_mode: str = ELASTIC,
        action_delay: int | DelaySpec = 0,
        obs_delay: int | DelaySpec = 0,
        link_delay: float | DelaySpec | None = None,
        action_delivery: str = NEWEST,
        obs_delivery: str = NEWEST,
        delayed_rewards: bool = False,
        seed: int | None = None,
        transport: str = "pipe",
        timeout: float | None = 60.0,
        startup_timeout: float = 60.0,
        call_timeouts: Mapping[str, float | None] | None = None,
        restart_on_failure: bool = False,
        max_restarts: int = 3,
        bind_host: str | None = None,
        curve: bool | None = None,
        launcher: SimGroup | None = None,
        attach: Any = None,
        **scene_kwargs: Any,
    ) -> None:
        self.render_mode = render_mode
        self.timeout = timeout
        self.startup_timeout = startup_timeout
        self.latency_stats = LatencyStats()
        self._last_obs: Any = None
        self.scene = os.fspath(scene)
        #: How the sim's world runs, as the arguments above ask (made and checked once, here).
        self.run_options = RunOptions(
            real_time=real_time,
            real_time_factor=real_time_factor,
            real_time_mode=real_time_mode,
            action_delay=action_delay,
            obs_delay=obs_delay,
            link_delay=link_delay,
            action_delivery=action_delivery,
            obs_delivery=obs_delivery,
            delayed_rewards=delayed_rewards,
        )
        group = choose_group(
            launcher, attach, attach_instances=[0], transport=transport, bind_host=bind_host, curve=curve
        )
        layout = group.layout
        if layout is not None and layout.num_instances != 1:
            raise ValueError(
                f"an OpenAIRemoteEnv drives one sim; {layout.source} has {layout.num_instances}: "
                "pick one (e.g. OpenAIRemoteEnv.attach(path, instance=i))"
            )
        self._session = open_session(
            group,
            scene_label(type(self).__name__, self.scene),
            self.scene,
            1,
            1,
            timeout=timeout,
            call_timeouts=call_timeouts,
            startup_timeout=startup_timeout,
            restart_on_failure=restart_on_failure,
            max_restarts=max_restarts,
            seed=seed,
            env_kwargs=scene_kwargs,
            render_mode=render_mode,
            run=self.run_options,
        )
        hs = self._session.handshake
        self.observation_space = hs.observation_space
        self.action_space = hs.action_space
        self.metadata = {"render_modes": list(hs.render_modes), "render_fps": hs.render_fps}
        #: Simulated seconds per step.
        self.dt: float = hs.dt
        self._timed_steps = hs.timed_steps
        self._pauser = Pauser(self._session)
        self._reach = SceneReach(self._session)

    @classmethod
    def attach(cls, launch_info: str | os.PathLike[str], instance: int = 0, **kwargs: Any) -> OpenAIRemoteEnv:
        """Drive sim ``instance`` of a launch-info file written by ``python -m
        remoteenv launch`` (or by any server speaking the protocol). ``kwargs``:
        ``render_mode`` (default: the one the sims were launched with),
        ``timeout``, ``call_timeouts``, ``startup_timeout`` (the handshake's).
        No time limit is applied; wrap in ``gymnasium.wrappers.TimeLimit`` or use
        ``gymnasium.make(env_id, attach=path)``. Closing the env leaves the sim running."""
        from remoteenv.agent.launch.attach import AttachedSims

        sims = AttachedSims(launch_info, [instance])
        kwargs.setdefault("render_mode", sims.info.render_mode)
        return cls(sims.scene, attach=sims, **kwargs)

    # ------------------------------------------------------------ state

    @property
    def pid(self) -> int | None:
        """Process id of the sim process (None once closed)."""
        pids = self._session.pids
        return pids[0] if pids else None

    @property
    def _conn(self) -> Any:
        """The connection to the sim (None once closed)."""
        conns = self._session.conns
        return conns[0] if conns else None

    def _request(self, cmd: str, **args: Any) -> dict[str, Any]:
        """Send ``cmd`` to the sim as is (no checks on this side) and wait for its reply."""
        return self._session.request(0, cmd, **args)

    # ------------------------------------------------------------ gym API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Start an episode in the sim. ``seed`` is forwarded and reseeds the sim's RNG."""
        super().reset(seed=seed)
        restarted: dict[str, Any] = {}
        while True:
            try:
                reply = restore_scalars(self._request("reset", seed=seed, options=options))
                break
            except RemoteEnvError as err:
                if not self._session.restarts.covers(err):
                    raise
                restarted = restarted_info(err, self._session.relaunch(0, err))
        self._last_obs = reply["obs"]
        return reply["obs"], {**reply["info"], **restarted}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Advance the sim by one control tick (``self.dt`` simulated seconds)."""
        wire_action = check_action(self.action_space, action)
        try:
            sent = time.perf_counter()
            reply = restore_scalars(self._request("step", action=wire_action))
            round_trip = time.perf_counter() - sent
        except RemoteEnvError as err:
            if not self._session.restarts.covers(err):
                raise
            info = restarted_info(err, self._session.relaunch(0, err))
            # The episode is lost with the process: end it as truncated at the
            # last observation the agent saw; the next reset() starts afresh.
            return self._last_obs, 0.0, False, True, info
        self._last_obs = reply["obs"]
        info = reply["info"]
        if self._timed_steps:
            info["wall_round_trip_s"] = round_trip
        self.latency_stats.record(info, round_trip)
        return reply["obs"], reply["reward"], reply["terminated"], reply["truncated"], info

    def render(self) -> np.ndarray | None:
        """With ``render_mode="rgb_array"``: the current frame, uint8 H x W x 3.
        With ``"human"``: redraw the sim's MuJoCo viewer window (it also redraws
        after every step) and return None."""
        if self.render_mode == "human":
            self._request("render")
            return None
        if self.render_mode != "rgb_array":
            return None
        return self._request("render")["frame"]

    def close(self) -> None:
        """Ask the sim to exit, then make sure it has (no process or socket file
        remains). An attached sim is left running."""
        session = getattr(self, "_session", None)
        if session is not None:
            session.close()
        super().close()
