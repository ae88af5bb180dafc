"""RemoteVectorEnv: N remote worlds stepped concurrently as one Gymnasium vector env.

Runs in the agent process. The N worlds live in ``ceil(N / K)`` sim processes
of K worlds each (``envs_per_process=K``). A vector step sends one request to
every process, then gathers the replies with one ``zmq.Poller``, so the
processes compute in parallel and the agent pays one round trip per step, not
one per world. In lock-step each request is a ``step_batch`` (K actions in,
K results out, see :mod:`remoteenv.protocol`); in real time each process hosts
one world and is driven with plain ``step``/``reset`` requests, so every world
keeps its own paced clock.
"""

from __future__ import annotations

import os
import time
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
import zmq
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from remoteenv.wire import protocol
from remoteenv.wire import spaces as spaces_codec
from remoteenv.wire.protocol import OP_RESET, OP_STEP, OP_STEP_AUTORESET, OP_STEP_RESET
from remoteenv.agent.connection import LIVENESS_CHECK_S, Connection, connect_sim
from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.wire.hot_wait import HotWait, yield_cpu
from remoteenv.agent.launcher import Launcher
from remoteenv.wire.actions import check_actions
from remoteenv.wire.batch import merge_infos
from remoteenv.agent.restart import RestartBudget, restarted_info


#: Longest busy-wait (seconds) of a vector call for its replies before sleeping;
#: calls whose replies took longer sleep at once (the sims need the CPUs).
GATHER_SPIN_S = 250e-6


def default_envs_per_process(num_envs: int) -> int:
    """K when ``envs_per_process`` is not given: at least 8 worlds per process,
    and no more processes than CPUs: ``max(8, ceil(N / cpu_count))``, capped at N.

    Every extra process costs a round trip per vector step (on a virtual
    machine, mostly the wake-up of a sleeping process, 20-40 us each) and its
    share of the agent's decoding; a second process pays off once it takes
    enough physics off the first. Measured side by side on the 2-core
    reference machine (Reacher, lock-step, one run): N = 4 and 8 stepped
    fastest in one process (K = N beat K = N/2 by 1.3x and 1.1x); N = 16
    fastest in two (K = 8 beat K = 16 by 1.15x); K = 1 was slowest at every
    N > 1.
    """
    per_cpu = -(-num_envs // max(1, os.cpu_count() or 1))
    return min(num_envs, max(8, per_cpu))


class RemoteVectorEnv(VectorEnv):
    """``num_envs`` worlds of one scene in sim processes, with Gymnasium 1.x vector semantics.

    Usually created with ``gymnasium.make_vec("remoteenv/Reacher-v0",
    num_envs=8, vectorization_mode="vector_entry_point")``. Keyword arguments
    not listed below go to the scene's env class (JSON-serializable).

    Args:
        scene: path of the scene script.
        num_envs: N, the number of worlds.
        envs_per_process: K, worlds hosted (and stepped from one request) by
            each sim process; ``ceil(N / K)`` processes are launched. Default
            ``max(8, ceil(N / cpu_count))`` capped at N: on a 2-core machine
            one process up to N = 8, then two up to N = 16; the fastest splits measured
            there (see :func:`default_envs_per_process`).
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
        real_time, real_time_factor, action_delay, transport, timeout,
        startup_timeout, bind_host, curve: as for
            :class:`remoteenv.OpenAIRemoteEnv`; ``timeout`` bounds the wait for
            all replies of one vector call.
        seed: seeds world ``i``'s RNG with ``seed + i`` until the first
            ``reset(seed=...)``.
        restart_on_failure, max_restarts: relaunch a sim process that dies or
            times out (at most ``max_restarts`` times over the env's life, all
            processes together). Its worlds' episodes end ``truncated`` at
            their last observation with reward 0 and
            ``info["remoteenv_restarted"] = True`` (with ``SAME_STEP`` the new
            episodes start in that step, the ended ones in ``final_obs``); a
            failed ``reset`` is retried on the new process.

    World ``i`` is world ``i % K`` of process ``i // K``. ``reset(seed=s)``
    seeds world ``i`` with ``s + i``, so a vector env and N single envs with
    the same seeds give the same trajectories, for any K.
    """

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
        action_delay: int = 0,
        seed: int | None = None,
        transport: str = "pipe",
        timeout: float | None = 60.0,
        startup_timeout: float = 60.0,
        bind_host: str | None = None,
        curve: bool | None = None,
        restart_on_failure: bool = False,
        max_restarts: int = 3,
        attach: Any = None,
        **scene_kwargs: Any,
    ) -> None:
        self.restarts = RestartBudget(restart_on_failure, max_restarts)
        self.startup_timeout = startup_timeout
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if attach is not None:  # drive the sims of a launch-info file, see :meth:`attach`
            from remoteenv.agent.attach import AttachedSims

            if restart_on_failure:
                raise ValueError("restart_on_failure needs sims this env launched; attached sims "
                                 "belong to the launch command")
            attach = attach if isinstance(attach, AttachedSims) else AttachedSims(attach)
            envs_per_process, real_time = attach.worlds_per_instance, attach.info.real_time
            if num_envs != attach.num_instances * envs_per_process:
                raise ValueError(
                    f"launch-info file {attach.info.path} serves {attach.num_instances * envs_per_process} "
                    f"worlds; pass num_envs={attach.num_instances * envs_per_process} (got {num_envs})"
                )
        if envs_per_process is None:
            envs_per_process = 1 if real_time else default_envs_per_process(num_envs)
        if envs_per_process < 1:
            raise ValueError(f"envs_per_process must be >= 1, got {envs_per_process}")
        if real_time and envs_per_process != 1:
            raise ValueError(
                f"real_time=True needs envs_per_process=1 (got {envs_per_process}): each sim "
                "process runs one paced clock, so it can host only one world"
            )
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be >= 1 or None, got {max_episode_steps}")
        self.num_envs = int(num_envs)
        self.envs_per_process = min(int(envs_per_process), self.num_envs)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        self.real_time = bool(real_time)
        self.timeout = timeout
        self.scene = os.fspath(scene)
        self.closed = False
        k = self.envs_per_process
        num_procs = -(-self.num_envs // k)
        #: ``(first, end)`` world indices of each process.
        self.slices: list[tuple[int, int]] = [
            (p * k, min((p + 1) * k, self.num_envs)) for p in range(num_procs)
        ]
        self._conns: list[Connection] = []
        self._launcher: Launcher | None = None
        self._launcher = attach if attach is not None else Launcher(
            self.scene,
            num_procs,
            seed=seed,
            worlds_per_instance=k,
            env_kwargs=scene_kwargs,
            render_mode=render_mode,
            transport=transport,
            startup_timeout=startup_timeout,
            real_time=real_time,
            real_time_factor=real_time_factor,
            action_delay=action_delay,
            bind_host=bind_host,
            curve=curve,
        )
        try:
            client = self._launcher.curve_client_keypair
            for sim in self._launcher.sims:
                self._conns.append(connect_sim(sim, timeout=timeout, curve_client_keypair=client))
            self._handshake(startup_timeout)
        except BaseException:
            self.close()
            raise
        n = self.num_envs
        self._elapsed = np.zeros(n, dtype=np.int64)
        self._autoreset = np.zeros(n, dtype=np.bool_)
        self._has_reset = False
        self._obs: Any = None
        self._poller: zmq.Poller | None = None
        self._poll_socks: list[Any] = []
        self._gather_hot = HotWait(GATHER_SPIN_S)

    # ------------------------------------------------------------ setup

    def _handshake(self, timeout: float) -> None:
        seqs = [c.send("handshake", protocol=protocol.PROTOCOL_VERSION) for c in self._conns]
        replies = [c.receive(s, timeout, what="'handshake'") for c, s in zip(self._conns, seqs)]
        hs = replies[0]
        self.handshake: dict[str, Any] = hs
        self.single_observation_space = spaces_codec.space_from_wire(hs["observation_space"])
        self.single_action_space = spaces_codec.space_from_wire(hs["action_space"])
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        meta = hs["metadata"]
        self.metadata = {
            "render_modes": list(meta["render_modes"]),
            "render_fps": meta["render_fps"],
            "autoreset_mode": self.autoreset_mode,
        }
        #: Simulated seconds per step.
        self.dt: float = float(meta["dt"])
        single_obs = self.single_observation_space
        self._box_obs = isinstance(single_obs, gym.spaces.Box)
        act = self.single_action_space
        self._box_act = isinstance(act, gym.spaces.Box)
        if self._box_act:
            self._act_low, self._act_high = act.low, act.high

    @classmethod
    def attach(cls, launch_info: str | os.PathLike[str], **kwargs: Any) -> "RemoteVectorEnv":
        """Drive every world of the sims named by a launch-info file (written by
        ``python -m remoteenv launch``) as one vector env: instance ``p``'s world
        ``w`` is world ``p * K + w``. ``kwargs``: ``autoreset_mode``,
        ``max_episode_steps`` (no limit unless given), ``render_mode`` (default:
        the sims'), ``timeout``, ``startup_timeout``. Closing leaves the sims running."""
        from remoteenv.agent.attach import AttachedSims

        sims = AttachedSims(launch_info)
        kwargs.setdefault("render_mode", sims.info.render_mode)
        return cls(sims.scene, sims.num_instances * sims.worlds_per_instance, attach=sims, **kwargs)

    @property
    def pids(self) -> list[int]:
        """Process ids of the sim processes (empty once closed)."""
        if self._launcher is None or self._launcher.closed:
            return []
        return self._launcher.pids

    @property
    def launcher(self) -> Launcher | None:
        return self._launcher

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
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            super().reset(seed=int(seed))
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = [None if s is None else int(s) for s in seed]
            if len(seeds) != n:
                raise ValueError(f"a list of seeds needs one per world: {n}, got {len(seeds)}")
        options = dict(options) if options is not None else None
        mask = np.ones(n, dtype=np.bool_)
        if options is not None and "reset_mask" in options:
            mask = options.pop("reset_mask")
            if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (n,):
                raise TypeError(
                    f"options['reset_mask'] must be a numpy bool array of shape ({n},), got {mask!r:.200}"
                )
            if not mask.any():
                raise ValueError("options['reset_mask'] must select at least one world")
            if not self._has_reset and not mask.all():
                raise RuntimeError("the first reset must reset every world; drop reset_mask")
        pending: dict[int, int] = {}
        worlds_of: dict[int, list[int]] = {}

        def send_reset(p: int) -> int:
            lo, worlds, conn = self.slices[p][0], worlds_of[p], self._conns[p]
            if self.real_time:
                return conn.send("reset", seed=seeds[lo], options=options)
            return conn.send(
                "reset_batch", worlds=worlds, seeds=[seeds[lo + w] for w in worlds], options=options
            )

        for p, (lo, hi) in enumerate(self.slices):
            worlds = [i - lo for i in range(lo, hi) if mask[i]]
            if not worlds:
                continue
            worlds_of[p] = worlds
            pending[p] = send_reset(p)
        replies, restarted = self._gather_restarting(pending, "reset", resend=send_reset)
        obs = self._new_obs_like_last(full=bool(mask.all()))
        infos: dict[str, Any] = {}
        for p, worlds in worlds_of.items():
            lo = self.slices[p][0]
            reply = replies[p]
            idx = np.asarray(worlds, dtype=np.intp) + lo
            if self.real_time:
                self._put_obs(obs, idx, [reply["obs"]])
                self._merge_info(infos, {"maps": [reply["info"]]}, idx)
            else:
                self._put_obs(obs, idx, reply["obs"])
                self._merge_info(infos, reply["info"], idx)
            if p in restarted:
                for i in idx:
                    self._add_info(infos, restarted_info(restarted[p], self.restarts.count), int(i))
        self._elapsed[mask] = 0
        self._autoreset[mask] = False
        self._has_reset = True
        self._obs = obs
        return self._return_obs(obs), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every world once (or autoreset it, see ``autoreset_mode``)."""
        if not self._has_reset:
            raise RuntimeError("step() before reset(): call reset() on the RemoteVectorEnv first")
        n = self.num_envs
        mode = self.autoreset_mode
        acts = self._check_actions(actions)
        limit = self.max_episode_steps
        if mode == AutoresetMode.NEXT_STEP:
            ops = np.where(self._autoreset, OP_RESET, OP_STEP)
        elif mode == AutoresetMode.SAME_STEP:
            ops = np.full(n, OP_STEP_AUTORESET)
            if limit is not None:
                ops[self._elapsed + 1 >= limit] = OP_STEP_RESET
        else:
            if self._autoreset.any():
                ended = np.flatnonzero(self._autoreset).tolist()
                raise RuntimeError(
                    f"worlds {ended} ended at the last step and autoreset_mode is DISABLED: reset "
                    "them with reset(options={'reset_mask': mask}) before stepping again"
                )
            ops = np.full(n, OP_STEP)
        if self.real_time or self.envs_per_process == 1:
            # One world per process: plain requests carry less than step_batch.
            results = self._step_single_worlds(ops, acts)
        else:
            ops_list = ops.tolist()
            pending = {
                p: self._conns[p].send("step_batch", ops=ops_list[lo:hi], actions=acts[lo:hi])
                for p, (lo, hi) in enumerate(self.slices)
            }
            results, failed = self._gather_restarting(pending, "step_batch")
            for p, err in failed.items():
                results[p] = self._restarted_results(p, err)
        obs, rewards, terminated, truncated, infos = self._assemble(results)

        stepped = ops != OP_RESET
        self._elapsed[stepped] += 1
        self._elapsed[~stepped] = 0
        if limit is not None:
            truncated |= stepped & (self._elapsed >= limit)
        ended = terminated | truncated
        if mode == AutoresetMode.SAME_STEP:
            self._elapsed[ended] = 0
            self._autoreset[:] = False
        else:
            self._autoreset = ended
        self._obs = obs
        return self._return_obs(obs), rewards, terminated, truncated, infos

    def render(self) -> tuple[Any, ...] | None:
        """With ``render_mode="rgb_array"``: one uint8 H x W x 3 frame per world."""
        if self.render_mode != "rgb_array":
            return None
        frames = []
        for p, (lo, hi) in enumerate(self.slices):
            for w in range(hi - lo):
                frames.append(self._conns[p].request("render", world=w)["frame"])
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        """Ask every sim to exit, then make sure they have (no process or socket file remains)."""
        conns, self._conns = self._conns, []
        seqs = []
        attached = getattr(self._launcher, "attached", False)  # attached sims outlive the env
        for conn in [] if attached else conns:
            try:
                seqs.append((conn, conn.send("close")))
            except (zmq.ZMQError, RemoteEnvError):
                pass
        for conn, seq in seqs:
            try:
                conn.receive(seq, 1.0, what="'close'")
            except RemoteEnvError:
                pass
        for conn in conns:
            conn.close()
        launcher, self._launcher = self._launcher, None
        if launcher is not None:
            launcher.close()

    def __del__(self) -> None:
        if not getattr(self, "closed", True):
            try:
                self.close()
            except Exception:
                pass

    # ------------------------------------------------------------ requests

    def _gather(
        self, pending: dict[int, int], cmd: str, replies: dict[int, dict[str, Any]] | None = None
    ) -> dict[int, dict[str, Any]]:
        """Wait for the reply to each ``{process: seq}`` in ``pending``; all in flight at once.
        Each reply goes into ``replies`` and its process leaves ``pending`` as it arrives."""
        what = f"'{cmd}'"
        if replies is None:
            replies = {}
        if len(pending) == 1:
            ((p, seq),) = pending.items()
            replies[p] = self._conns[p].receive(seq, what=what)
            del pending[p]
            return replies
        conns = self._conns
        poller = self._poller_for(conns)
        socket_index = self._socket_index
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        hot = self._gather_hot
        started = time.perf_counter()
        hot_until = started + hot.window_s if hot.worth_it() else started
        while pending:
            # While replies have been quick, poll without sleeping first (see
            # remoteenv.wire.hot_wait), yielding the CPU to any process that shares it.
            events = poller.poll(0)
            while not events and time.perf_counter() < hot_until:
                yield_cpu()
                events = poller.poll(0)
            if not events:
                events = poller.poll(LIVENESS_CHECK_S * 1000)
            for sock, _ in events:
                p = socket_index[sock]
                seq = pending.get(p)
                if seq is None:
                    try:
                        conns[p].try_receive(-2, what)  # drop stale replies
                    except RemoteEnvError:
                        pass
                    continue
                reply = conns[p].try_receive(seq, what)
                if reply is not None:
                    replies[p] = reply
                    del pending[p]
            if not events:
                for p in pending:
                    conns[p].check_alive(what)
                if deadline is not None and time.monotonic() > deadline:
                    p = next(iter(pending))
                    for q in pending:
                        conns[q].reconnect()
                    self._poller = None
                    raise RemoteEnvTimeout(
                        f"sim instance {p} (and {len(pending) - 1} more) at {conns[p].endpoint} "
                        f"did not answer {what} within {self.timeout:g} s; the process is alive but "
                        "stuck or overloaded. Raise the vector env's timeout= or check the scene "
                        "code. The connections were rebuilt; the next call can go ahead.",
                        kind="timeout",
                        instance=p,
                    )
        hot.waited(time.perf_counter() - started)
        return replies

    def _poller_for(self, conns: list[Connection]) -> zmq.Poller:
        socks = [c.pollable for c in conns]
        if self._poller is None or socks != self._poll_socks:
            poller = zmq.Poller()
            for sock in socks:
                poller.register(sock, zmq.POLLIN)
            self._poller, self._poll_socks = poller, socks
            self._socket_index = {sock: p for p, sock in enumerate(socks)}
        return self._poller

    def _step_single_worlds(self, ops: np.ndarray, acts: Any) -> dict[int, dict[str, Any]]:
        """Real time: one world per process, plain ``step``/``reset`` requests, results in
        ``step_batch`` form."""
        pending = {}
        for p, (lo, _) in enumerate(self.slices):
            conn = self._conns[p]
            if ops[lo] == OP_RESET:
                pending[p] = conn.send("reset", seed=None, options=None)
            else:
                pending[p] = conn.send("step", action=acts[lo])
        replies, failed = self._gather_restarting(pending, "step")
        results: dict[int, dict[str, Any]] = {p: self._restarted_results(p, e) for p, e in failed.items()}
        resets: dict[int, int] = {}
        for p, r in replies.items():
            lo = self.slices[p][0]
            if ops[lo] == OP_RESET:
                results[p] = {"obs": [r["obs"]], "reward": [0.0], "terminated": [False],
                              "truncated": [False], "info": {"maps": [r["info"]]}, "final": []}
                continue
            results[p] = {"obs": [r["obs"]], "reward": [r["reward"]], "terminated": [r["terminated"]],
                          "truncated": [r["truncated"]], "info": {"maps": [r["info"]]}, "final": []}
            if ops[lo] == OP_STEP_RESET or (ops[lo] == OP_STEP_AUTORESET and (r["terminated"] or r["truncated"])):
                resets[p] = self._conns[p].send("reset", seed=None, options=None)
        for p, r in self._gather(resets, "reset").items():
            res = results[p]
            res["final"] = [[0, res["obs"][0], res["info"]["maps"][0]]]
            res["obs"] = [r["obs"]]
            res["info"] = {"maps": [r["info"]]}
        return results

    # ------------------------------------------------------------ restarts

    def _gather_restarting(
        self, pending: dict[int, int], cmd: str, resend: Any = None
    ) -> tuple[dict[int, dict[str, Any]], dict[int, RemoteEnvError]]:
        """:meth:`_gather`, relaunching each process that dies or times out when
        ``restart_on_failure`` is on. ``resend(p)`` sends ``p``'s request again to
        its new process; without it ``p`` has no reply. Returns the replies and
        ``{process: error}`` of the processes relaunched."""
        replies: dict[int, dict[str, Any]] = {}
        failed: dict[int, RemoteEnvError] = {}
        while pending:
            try:
                self._gather(pending, cmd, replies)
            except RemoteEnvError as err:
                if not self.restarts.covers(err) or err.instance not in pending:
                    raise
                lost = list(pending) if err.kind == "timeout" else [err.instance]
                for p in lost:
                    del pending[p]
                    failed[p] = err
                    self._relaunch(p, err)
                    if resend is not None:
                        pending[p] = resend(p)
        return replies, failed

    def _relaunch(self, p: int, err: RemoteEnvError) -> None:
        """Kill process ``p`` if it still runs and launch it afresh, spending
        restarts (one per attempt) until one comes up; raises when none are left."""
        assert self._launcher is not None
        while True:
            self.restarts.spend(err)
            self._conns[p].close()
            self._poller = None
            try:
                sim = self._launcher.restart(p)
                self._conns[p] = connect_sim(
                    sim, timeout=self.timeout, curve_client_keypair=self._launcher.curve_client_keypair
                )
                self._conns[p].request("handshake", timeout=self.startup_timeout,
                                       protocol=protocol.PROTOCOL_VERSION)
                return
            except RemoteEnvError as again:
                err = again

    def _restarted_results(self, p: int, err: RemoteEnvError) -> dict[str, Any]:
        """``step_batch``-form results for the worlds of relaunched process ``p``:
        truncated at their last observation, reward 0, the restart in their info."""
        lo, hi = self.slices[p]
        k = hi - lo
        info = restarted_info(err, self.restarts.count)
        last = [np.array(self._obs[i]) if self._box_obs else self._obs[i] for i in range(lo, hi)]
        result: dict[str, Any] = {
            "obs": last, "reward": [0.0] * k, "terminated": [False] * k, "truncated": [True] * k,
            "info": {"maps": [dict(info) for _ in range(k)]}, "final": [],
        }
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            # The new episodes start in this step; the ended ones go to final_obs.
            if self.real_time:
                fresh = [self._conns[p].request("reset", seed=None, options=None)["obs"]]
            else:
                fresh = self._conns[p].request(
                    "reset_batch", worlds=list(range(k)), seeds=[None] * k, options=None)["obs"]
            result["obs"] = fresh
            result["final"] = [[w, last[w], dict(info)] for w in range(k)]
        return result

    # ------------------------------------------------------------ batching

    def _check_actions(self, actions: Any) -> Any:
        """The N actions in wire form, indexable by world; ValueError names the world."""
        n = self.num_envs
        space = self.single_action_space
        if self._box_act:
            return check_actions(space, np.asarray(actions), n)
        checked = check_actions(space, list(iterate(self.action_space, actions)), n)
        if isinstance(space, gym.spaces.Discrete):
            return np.asarray(checked, dtype=np.int64)
        return checked

    def _assemble(self, results: dict[int, dict[str, Any]]) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        n = self.num_envs
        infos: dict[str, Any] = {}
        if len(results) == 1 and self._box_obs and isinstance(results[0]["obs"], np.ndarray):
            r = results[0]  # one process: its fresh arrays are the batch
            obs = r["obs"]
            rewards = np.asarray(r["reward"], dtype=np.float64)
            terminated = np.asarray(r["terminated"], dtype=np.bool_)
            truncated = np.asarray(r["truncated"], dtype=np.bool_)
            idx = np.arange(n)
            for w, fobs, finfo in r["final"]:
                self._add_info(infos, {"final_obs": fobs, "final_info": finfo}, w)
            self._merge_info(infos, r["info"], idx)
            return obs, rewards, terminated, truncated, infos
        obs = self._new_obs_like_last(full=True)
        rewards = np.empty(n, dtype=np.float64)
        terminated = np.empty(n, dtype=np.bool_)
        truncated = np.empty(n, dtype=np.bool_)
        for p, (lo, hi) in enumerate(self.slices):
            r = results[p]
            idx = np.arange(lo, hi)
            self._put_obs(obs, idx, r["obs"])
            rewards[lo:hi] = r["reward"]
            terminated[lo:hi] = r["terminated"]
            truncated[lo:hi] = r["truncated"]
            for w, fobs, finfo in r["final"]:
                self._add_info(infos, {"final_obs": fobs, "final_info": finfo}, lo + w)
            self._merge_info(infos, r["info"], idx)
        return obs, rewards, terminated, truncated, infos

    def _merge_info(self, infos: dict[str, Any], packed: dict[str, Any], idx: np.ndarray) -> None:
        merge_infos(infos, packed, idx, self.num_envs, self._add_info)

    def _new_obs_like_last(self, full: bool) -> Any:
        """A fresh obs batch: empty if every world will be written, else a copy of the last one."""
        if self._box_obs:
            if full or self._obs is None:
                space = self.single_observation_space
                return np.empty((self.num_envs, *space.shape), dtype=space.dtype)
            return self._obs.copy()
        if full or self._obs is None:
            return [None] * self.num_envs
        return list(self._obs)

    def _put_obs(self, obs: Any, idx: np.ndarray, items: Any) -> None:
        if self._box_obs:
            obs[idx] = items if isinstance(items, np.ndarray) else np.stack(items)
        else:
            for j, i in enumerate(idx):
                obs[int(i)] = items[j]

    def _return_obs(self, obs: Any) -> Any:
        if self._box_obs:
            return obs
        space = self.single_observation_space
        return concatenate(space, obs, create_empty_array(space, self.num_envs))
