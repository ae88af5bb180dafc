"""RemoteVectorEnv: N remote worlds stepped concurrently as one Gymnasium vector env.

Runs in the agent process. The N worlds live in ``ceil(N / K)`` sim processes
of K worlds each (``envs_per_process=K``). A vector step sends one request to
every process, then gathers the replies with one ``zmq.Poller``, so the
processes compute in parallel and the agent pays one round trip per step, not
one per world. In lock-step each request is a ``step_batch`` (K actions in,
K results out, see :mod:`remoteenv.protocol`); in real time each process hosts
one world and is driven with plain ``step``/``reset`` requests, so every world
keeps its own paced clock.

The class keeps Gymnasium's vector semantics; the jobs under it live in
:mod:`remoteenv.agent`: the sims' lifecycle (:mod:`~remoteenv.agent.session.sim_session`),
the requests of a call and their gathering (:mod:`~remoteenv.agent.vector.vector_episodes`,
:mod:`~remoteenv.agent.vector.vector_requests`,
:mod:`~remoteenv.agent.connection.fan_in`), autoreset planning
(:mod:`~remoteenv.agent.vector.autoreset`), reset arguments
(:mod:`~remoteenv.agent.session.reset_args`), result assembly
(:mod:`~remoteenv.agent.vector.vector_results`) and restarts (:mod:`~remoteenv.agent.launch.restart`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from remoteenv.agent.launch.sim_group import SimGroup
from remoteenv.agent.session.forwarding import SceneReach, VectorAttributes
from remoteenv.agent.session.latency_stats import LatencyStats
from remoteenv.agent.session.pausing import Pausable, Pauser
from remoteenv.agent.session.pickling import RebuildOnUnpickle, remember_init_args
from remoteenv.agent.session.reset_args import is_int_seed
from remoteenv.agent.session.session_attributes import SessionAttributes
from remoteenv.agent.session.sim_session import choose_group, scene_label
from remoteenv.agent.vector.pool_api import PoolAPI
from remoteenv.agent.vector.sim_placement import SimPlacement, check_place_sims
from remoteenv.agent.vector.torch_threads import AUTO, TorchThreads, check_torch_threads
from remoteenv.agent.vector.vector_episodes import VectorEpisodes
from remoteenv.agent.vector.vector_launch import open_worlds
from remoteenv.agent.vector.vector_layout import (
    cost_may_change_layout,
    default_envs_per_process,
    plan_layout,
    world_slices,
)
from remoteenv.agent.vector.vector_results import hold_big_ints, hold_nones
from remoteenv.wire.delays.channel_rules import NEWEST
from remoteenv.wire.delays.delay_specs import DelaySpec
from remoteenv.wire.messages.handshake import Handshake
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import ELASTIC

__all__ = ["RemoteVectorEnv", "default_envs_per_process"]


class RemoteVectorEnv(SessionAttributes, VectorAttributes, Pausable, PoolAPI, RebuildOnUnpickle, VectorEnv):
    """``num_envs`` worlds of one scene in sim processes, with Gymnasium 1.x vector semantics.

    Usually created with ``gymnasium.make_vec("remoteenv/Reacher-v0",
    num_envs=8, vectorization_mode="vector_entry_point")``. Keyword arguments
    not listed below go to the scene's env class (JSON-serializable).

    Args:
        scene: path of the scene script.
        num_envs: N, the number of worlds.
        envs_per_process: K, worlds hosted (and stepped from one request) by
            each sim process; ``ceil(N / K)`` processes are launched. Default:
            cheap worlds whose scene steps them as one batch, and which that
            rule would spread over two processes or more (N >= 9 on 2 CPUs),
            run in one process, their physics on ``min(cpu_count, N // 4)``
            threads (:attr:`physics_threads`); otherwise ``max(8, ceil(N /
            cpu_count))`` capped at N (on a 2-core machine one process up to N
            = 8); the fastest layouts measured there (see
            :func:`default_envs_per_process`). Where what a world costs could
            change K, a sim measures one world's whole tick (physics and
            every hook, however the scene renders: :attr:`world_cost_s`) and
            says whether its scene steps its worlds as one batch: when the
            scene script sets ``stacked_hooks = True``, the first sim of the
            one-process layout measures a scratch world before building
            its worlds and goes on only if that is their layout (the layout
            gate; otherwise it ends unbuilt and the worlds start once, in
            theirs); else the first launch, a process per CPU, which is
            relaunched once if the handshake calls for another layout.
            Must be 1 with ``real_time``.
        autoreset_mode: Gymnasium's :class:`~gymnasium.vector.AutoresetMode`
            (or its string): ``NEXT_STEP`` (default; the step after an episode
            ends resets that world, ignores its action and returns reward 0,
            not terminated, not truncated), ``SAME_STEP`` (the world is reset
            in the step that ends it; ``info["final_obs"]`` and
            ``info["final_info"]`` hold the last obs and info) or ``DISABLED``
            (reset ended worlds with ``reset(options={"reset_mask": mask})``).
        max_episode_steps: truncate an episode after this many steps (what
            ``TimeLimit`` does for single envs; ``make_vec`` passes the spec's).
        render_mode: ``"rgb_array"``: :meth:`render` returns one frame per world.
        real_time, real_time_factor, real_time_mode, action_delay, obs_delay, link_delay,
            action_delivery, obs_delivery, delayed_rewards, transport, timeout,
        startup_timeout, call_timeouts, bind_host, curve: as for
            :class:`remoteenv.OpenAIRemoteEnv`; ``timeout`` (or the call's entry
            in ``call_timeouts``) bounds the wait for all replies of one vector call;
            each world draws its own delays. ``pause()``/``resume()``/``paused()`` likewise.
        seed: seeds world ``i``'s RNG with ``seed + i`` until the first
            ``reset(seed=...)``.
        restart_on_failure, max_restarts: relaunch a sim process that dies or
            times out (at most ``max_restarts`` times over the env's life, all
            processes together). Its worlds' episodes end ``truncated`` at
            their last observation with reward 0 and
            ``info["remoteenv_restarted"] = True`` (with ``SAME_STEP`` the new
            episodes start in that step, the ended ones in ``final_obs``); a
            failed ``reset`` is retried on the new process.
        launcher: the :class:`~remoteenv.agent.launch.sim_group.SimGroup` that starts
            the sims (default: a local :class:`remoteenv.Launcher` with
            ``transport``, ``bind_host`` and ``curve``). A group whose layout is
            fixed already is driven as it is: ``num_envs`` must match it, and
            its worlds per instance and stepping are taken. The env closes the
            group when it closes.
        attach: a launch-info path (or :class:`~remoteenv.agent.launch.attach.AttachedSims`):
            drive every world of those sims (see :meth:`attach`).
        batch_size: worlds :meth:`recv` returns (EnvPool's asynchronous API,
            :class:`~remoteenv.agent.vector.pool_api.PoolAPI`, lock-step only);
            default ``num_envs``.
        torch_threads: ``"auto"`` (default): when torch is loaded in this
            process, lower its CPU threads once to the CPUs this env's sims
            leave free (at least one), with a warning that says so, unless
            ``OMP_NUM_THREADS`` is set (:mod:`~remoteenv.agent.vector.torch_threads`),
            and in lock step give them back for the learner's update when
            that measures faster (:mod:`~remoteenv.agent.vector.update_threads`);
            None: leave torch alone; an int: set that many threads.
        place_sims: ``"auto"`` (default): the sims this env starts on this
            machine run as batch work, pinned one to a CPU when they fit, in
            lock step only (:mod:`~remoteenv.agent.vector.sim_placement`);
            None: leave them to the OS scheduler.

    World ``i`` is world ``i % K`` of process ``i // K``. ``reset(seed=s)``
    seeds world ``i`` with ``s + i``, so a vector env and N single envs with
    the same seeds give the same trajectories, for any K.

    ``call``, ``get_attr`` and ``set_attr`` follow Gymnasium's vector API and
    reach each world's scene (:class:`~remoteenv.agent.session.forwarding.VectorAttributes`),
    e.g. ``set_attr("pole_mass", [0.05, 0.1, 0.2])`` for per-world model
    parameters. Pickling or ``copy.deepcopy`` builds a new env from the same
    constructor arguments, with fresh sims.

    Attributes:
        run_options: the run options the arguments above make
            (:class:`~remoteenv.wire.run_options.options.RunOptions`: real time, its
            factor and regime, the delays and their rules), checked once and sent
            whole to the sims (attached sims run what they were launched with).
        world_cost_s: what one world's whole control tick costs its sim on one
            thread (seconds), where the default layout measured it (or an
            earlier vector env of the same scene and arguments in this process
            did: :mod:`~remoteenv.agent.vector.layout_memory`); else None.
        latency_stats: :class:`remoteenv.agent.session.latency_stats.LatencyStats` of every
            vector step so far: one wall round trip per call, and with
            ``real_time`` or ``action_delay`` each world's action latency.
    """

    @remember_init_args
    def __init__(
        self,
        scene: str | os.PathLike[str],
        num_envs: int = 1,
        *,
        envs_per_process: int | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
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
        bind_host: str | None = None,
        curve: bool | None = None,
        restart_on_failure: bool = False,
        max_restarts: int = 3,
        launcher: SimGroup | None = None,
        attach: Any = None,
        batch_size: int | None = None,
        torch_threads: int | str | None = AUTO,
        place_sims: str | None = AUTO,
        **scene_kwargs: Any,
    ) -> None:
        self.startup_timeout = startup_timeout
        check_torch_threads(torch_threads)
        check_place_sims(place_sims)
        #: How the sims' worlds run, as the arguments ask (made and checked once, here).
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
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        group = choose_group(launcher, attach, transport=transport, bind_host=bind_host, curve=curve)
        layout = group.layout
        asked = envs_per_process
        envs_per_process, real_time = plan_layout(
            num_envs, envs_per_process, real_time, layout, max_episode_steps=max_episode_steps, batch_size=batch_size
        )
        #: Worlds :meth:`recv` returns.
        self.batch_size = int(batch_size or num_envs)
        self.num_envs = int(num_envs)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        self.real_time = bool(real_time)
        self.timeout = timeout
        self.scene = os.fspath(scene)
        self.closed = False
        launch: dict[str, Any] = {
            "timeout": timeout,
            "call_timeouts": call_timeouts,
            "startup_timeout": startup_timeout,
            "restart_on_failure": restart_on_failure,
            "max_restarts": max_restarts,
            "seed": seed,
            "env_kwargs": scene_kwargs,
            "render_mode": render_mode,
            "run": self.run_options,
        }
        default_layout = asked is None and launcher is None and attach is None and not self.real_time
        self._session, self.envs_per_process, self.world_cost_s = open_worlds(
            group,
            scene_label(type(self).__name__, self.scene),
            self.scene,
            self.num_envs,
            int(envs_per_process),
            launch,
            regroup=(lambda: choose_group(None, None, transport=transport, bind_host=bind_host, curve=curve))
            if default_layout
            else None,
            measure_cost=default_layout and cost_may_change_layout(self.num_envs),
        )
        #: ``(first, end)`` world indices of each process.
        self.slices: list[tuple[int, int]] = world_slices(self.num_envs, self.envs_per_process)
        #: Threads each sim process steps its worlds' physics on, as the first sim's handshake says
        #: (the default layout's one process of cheap worlds steps on several; 1 if it does not say).
        self.physics_threads: int = self._session.handshake.physics_threads or 1
        try:
            self._set_spaces(self._session.handshake)
            self._episodes = VectorEpisodes(
                self._session, self.slices, self.autoreset_mode, self.max_episode_steps, self.real_time, self.batch_size
            )
        except BaseException:
            self._session.close()
            raise
        self._requests = self._episodes.requests
        self.latency_stats = LatencyStats()
        self._pauser = Pauser(self._session)
        self._reach = SceneReach(self._session)
        # In real time the sims run on through the caller's update: it gets no CPUs back then.
        away = None if self.real_time else self._requests.lanes.away
        self._torch_threads = TorchThreads(torch_threads, self._session.local_sims * self.physics_threads, away=away)
        self._torch_threads.apply()
        own = launcher is None and attach is None and self._session.local_sims == len(self._session.pids)
        self._placement = SimPlacement(place_sims, own_sims=own, real_time=self.real_time)
        self._placement.apply(self._session.pids)

    def _set_spaces(self, hs: Handshake) -> None:
        self.single_observation_space = hs.observation_space
        self.single_action_space = hs.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = {
            "render_modes": list(hs.render_modes),
            "render_fps": hs.render_fps,
            "autoreset_mode": self.autoreset_mode,
        }
        #: Simulated seconds per step.
        self.dt: float = hs.dt

    @classmethod
    def attach(cls, launch_info: str | os.PathLike[str], **kwargs: Any) -> RemoteVectorEnv:
        """Drive every world of the sims named by a launch-info file (written by
        ``python -m remoteenv launch``) as one vector env: instance ``p``'s world
        ``w`` is world ``p * K + w``. ``kwargs``: ``autoreset_mode``,
        ``max_episode_steps`` (no limit unless given), ``render_mode`` (default:
        the sims'), ``timeout``, ``call_timeouts``, ``startup_timeout``. Closing
        leaves the sims running."""
        from remoteenv.agent.launch.attach import AttachedSims

        sims = AttachedSims(launch_info)
        kwargs.setdefault("render_mode", sims.info.render_mode)
        return cls(sims.scene, sims.layout.num_worlds, attach=sims, **kwargs)

    # ------------------------------------------------------------ state

    @property
    def pids(self) -> list[int | None]:
        """Process ids of the sim processes (empty once closed)."""
        return self._session.pids

    # ------------------------------------------------------------ gym API

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every world, or with ``options={"reset_mask": mask}`` (bool array of
        N) only the masked ones; the others keep their current obs. ``seed``: an
        int seeds world ``i`` with ``seed + i``; a list gives one seed (or None)
        per world. Other options go to every reset world's scene."""
        self._episodes.check_idle()
        self._torch_threads.interrupted()
        self._torch_threads.apply()
        self._placement.apply(self._session.pids)
        if is_int_seed(seed):
            super().reset(seed=int(seed))  # type: ignore[arg-type]
        return self._episodes.reset(seed, options, self._add_info)

    def _add_info(self, vector_infos: dict[str, Any], env_info: dict[str, Any], env_num: int) -> dict[str, Any]:
        """Gymnasium's merge of one world's info, after :func:`~remoteenv.agent.vector.vector_results.hold_nones`
        and :func:`~remoteenv.agent.vector.vector_results.hold_big_ints`."""
        held = hold_big_ints(hold_nones(vector_infos, env_info, self.num_envs), env_info, self.num_envs)
        return super()._add_info(held, env_info, env_num)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every world once (or autoreset it, see ``autoreset_mode``)."""
        self.step_async(actions)
        return self.step_wait()

    def step_async(self, actions: Any) -> None:
        """Send the actions of every world and return at once; :meth:`step_wait`
        gathers the results (together the same as :meth:`step`)."""
        self._torch_threads.step_starts()
        self._episodes.start_step(actions)

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """The results of the step :meth:`step_async` sent, as :meth:`step` returns them."""
        result, round_trip = self._episodes.finish_step(self._add_info)
        self.latency_stats.record_vector(result[4], round_trip)
        self._torch_threads.step_returns()
        return result

    @property
    def np_random_seed(self) -> tuple[int, ...]:  # type: ignore[override]
        """Each world's RNG seed, as ``SyncVectorEnv`` gives its envs' (``get_attr("np_random_seed")``)."""
        return self.get_attr("np_random_seed")

    def close_extras(self, **kwargs: Any) -> None:
        """Ask every sim to exit, then make sure they have (no process or socket
        file remains). Attached sims are left running."""
        torch_threads = getattr(self, "_torch_threads", None)
        if torch_threads is not None:
            torch_threads.interrupted()
        requests = getattr(self, "_requests", None)
        if requests is not None:
            requests.lanes.close()
        session = getattr(self, "_session", None)
        if session is not None:
            session.close()

    def __del__(self) -> None:
        if not getattr(self, "closed", True):
            try:
                self.close()
            except Exception:
                pass
