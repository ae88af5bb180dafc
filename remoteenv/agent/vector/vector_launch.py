"""Starting a vector env's sims in the layout that what one world costs gives.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`).
"""

from __future__ import annotations

import dataclasses
import os
import signal
import threading
from collections.abc import Callable
from typing import Any

from remoteenv.agent.errors import BatchTooLargeError, LimitError
from remoteenv.agent.launch.launcher import Launcher
from remoteenv.agent.launch.layout_gate import GateFacts, LayoutRejected
from remoteenv.agent.launch.sim_group import SimGroup
from remoteenv.agent.session.scene_signature import declares_stacked_hooks
from remoteenv.agent.session.sim_session import SimSession, open_session
from remoteenv.agent.vector.layout_memory import WorldFacts, recall, remember, scene_key
from remoteenv.agent.vector.sim_placement import SIM_THREADS_ENV
from remoteenv.agent.vector.vector_layout import default_envs_per_process, layout_threads, world_slices
from remoteenv.wire.codec.spaces import value_nbytes
from remoteenv.wire.memory import worlds_problem
from remoteenv.wire.messages.handshake import Handshake, worlds_that_fit


def open_worlds(
    group: SimGroup,
    label: str,
    scene: str,
    num_envs: int,
    envs_per_process: int,
    launch: dict[str, Any],
    *,
    regroup: Callable[[], SimGroup] | None = None,
    measure_cost: bool = False,
) -> tuple[SimSession, int, float | None]:
    """Start (or take) the sims of ``num_envs`` worlds, ``envs_per_process`` (K,
    capped at ``num_envs``) each: the open session, the K it runs, and what one
    world's tick costs (seconds; None unless measured).

    ``launch``: :func:`~remoteenv.agent.session.sim_session.open_session`'s options.
    ``regroup`` (given for the default layout only): the worlds are placed
    from what one costs (with ``measure_cost``: one world's whole tick,
    physics and every hook however the scene renders, the handshake's
    ``world_cost_s``, see :mod:`remoteenv.sim.scene.world_cost`), whether
    the scene steps its worlds as one batch, and how many observations one
    reply carries (:func:`~remoteenv.agent.vector.vector_layout.default_envs_per_process`).
    Where the scene script says it steps its worlds as one batch
    (:func:`~remoteenv.agent.session.scene_signature.declares_stacked_hooks`:
    cheap ones then move into one process) the layout of cheap worlds is
    started from ``group`` through the layout gate
    (:mod:`~remoteenv.agent.launch.layout_gate`): its sim measures a scratch
    world before building any, and goes on only if that measurement gives
    this layout; else it ends unbuilt and the worlds start once, in the
    layout it gives, from ``regroup()``. Where a scratch world would not show
    how the served ones step (lock-step delays, a viewer window) a probe asks
    first instead, one sim of one world, closed once it has answered.
    Otherwise the first launch (a
    process per CPU: right for costly worlds and for a scene whose Python
    runs per world) is asked, and if its handshake gives another K, its sims
    are closed and relaunched once from ``regroup()``. K is also at most
    what one batch reply carries the observations of (a process of 8 worlds
    of 1280x1280 pixels, 39 MB, would be refused: it gets 6): a first launch
    refused for that is placed again the same way. The default layout's processes get its physics
    threads (:func:`~remoteenv.agent.vector.vector_layout.layout_threads`,
    in the run options) unless ``REMOTEENV_SIM_THREADS`` sets them. What a
    measuring handshake said is remembered for this process
    (:mod:`~remoteenv.agent.vector.layout_memory`): a later default layout of
    the same scene and arguments starts where this one ended, measuring
    nothing (the cost returned is the one remembered).
    """
    per_process = min(envs_per_process, num_envs)

    def start(source: SimGroup, k: int, measure: bool = False) -> SimSession:
        slices = len(world_slices(num_envs, k))
        options = launch
        if regroup is not None:
            run = dataclasses.replace(launch["run"], physics_threads=default_layout_threads(num_envs, k))
            options = {**launch, "run": run}
        return open_session(source, label, scene, slices, k, measure_world_cost=measure, **options)

    key = scene_key(scene, launch.get("env_kwargs") or {}, launch.get("render_mode")) if measure_cost else None
    known = recall(key) if regroup is not None else None
    probe_exit: threading.Thread | None = None
    gated: SimSession | None = None
    if known is None and measure_cost and regroup is not None and declares_stacked_hooks(scene):
        if isinstance(group, Launcher) and _gate_fits(group, launch):
            known, gated = _through_gate(group, num_envs, start)
            if gated is None:
                group = regroup()
        else:
            known, probe_exit = _probe(group, label, scene, launch)
            group = regroup()
        if known.cost_s is not None:
            remember(key, known)
    if known is not None:  # learnt by the gate, the probe or an earlier vector env of this scene
        per_process = _placed(num_envs, known)
        measure_cost = False
    try:
        session = gated if gated is not None else start(group, per_process, measure_cost)
    except BatchTooLargeError as exc:
        # The default layout put more worlds in a process than one batch reply
        # carries the observations of: place them again so that each fits.
        if regroup is None or not 1 <= exc.worlds_that_fit < per_process:
            raise
        per_process = exc.worlds_that_fit
        return _bounded(start(regroup(), per_process), num_envs, label), per_process, None
    finally:
        if probe_exit is not None:
            probe_exit.join()
    _bounded(session, num_envs, label)
    handshake = session.handshake
    cost = handshake.world_cost_s
    if regroup is None:
        return session, per_process, cost
    if known is not None:
        cost = known.cost_s
    facts = _facts(handshake, cost)
    if cost is not None:
        remember(key, facts)
    better = _placed(num_envs, facts)
    if better == per_process:
        return session, per_process, cost
    closing = _closing(session, f"{label}: closing the first layout's sims")
    try:
        return start(regroup(), better), better, cost
    finally:
        closing.join()


def _probe(group: SimGroup, label: str, scene: str, launch: dict[str, Any]) -> tuple[WorldFacts, threading.Thread]:
    """What one sim of one world from ``group`` says of the scene's worlds (its
    measured cost among them), and the thread on which that sim is closing
    (see :func:`_closing`)."""
    session = open_session(group, f"{label} (probe)", scene, 1, 1, measure_world_cost=True, probe=True, **launch)
    return _facts(session.handshake, session.handshake.world_cost_s), _closing(session, f"{label}: closing the probe")


def _gate_fits(group: Launcher, launch: dict[str, Any]) -> bool:
    """Whether ``group`` (this machine's launcher) can start its sims through
    the layout gate: not started yet, for sims whose worlds may step as one
    batch as a scratch world does (no lock-step delays, no viewer window), on
    an OS where a sim can wait for the go."""
    return (
        group.layout is None
        and launch.get("render_mode") != "human"
        and not launch["run"].lock_step_delayed
        and hasattr(signal, "SIGUSR1")  # the go (POSIX)
    )


def _through_gate(
    group: Launcher, num_envs: int, start: Callable[[SimGroup, int], SimSession]
) -> tuple[WorldFacts, SimSession | None]:
    """Start the layout of cheap worlds stepped as one batch, its first sim
    gated (:mod:`~remoteenv.agent.launch.layout_gate`): it measures a scratch
    world first, and builds its own only if that measurement calls for this
    layout. What it measured, and the open session (None: turned down, every
    sim stopped before building a world)."""
    guess = _placed(num_envs, WorldFacts(0.0, True, num_envs))
    measured: list[WorldFacts] = []

    def agrees(facts: GateFacts) -> bool:
        measured.append(WorldFacts(facts.cost_s, facts.stacked_hooks, facts.fit))
        return _placed(num_envs, measured[0]) == guess

    group.layout_gate = agrees
    try:
        session = start(group, guess)
    except LayoutRejected:
        return measured[0], None
    return measured[0], session


def _facts(handshake: Handshake, cost_s: float | None) -> WorldFacts:
    """What ``handshake`` says of its scene's worlds, with ``cost_s`` as one world's cost."""
    return WorldFacts(cost_s, handshake.stacked_hooks, worlds_that_fit(handshake.observation_space))


def _closing(session: SimSession, name: str) -> threading.Thread:
    """``session`` closing on a thread of its own, which the caller joins: its
    sims exit while the caller starts others (an exit is ~30 ms of each sim's
    CPU: its interpreter's teardown)."""
    thread = threading.Thread(target=session.close, name=name, daemon=True)
    thread.start()
    return thread


def _placed(num_envs: int, facts: WorldFacts) -> int:
    """K for ``num_envs`` worlds of which ``facts`` are known: the rule's
    (:func:`~remoteenv.agent.vector.vector_layout.default_envs_per_process`),
    at most what one batch reply carries."""
    stacked = facts.stacked_hooks is not False  # a server that does not say keeps the rule's first guess
    return min(default_envs_per_process(num_envs, facts.cost_s, stacked), num_envs, max(1, facts.fit))


def _bounded(session: SimSession, num_envs: int, label: str) -> SimSession:
    """``session``, unless the agent's buffers for ``num_envs`` observations
    (a batch, the final observations of an autoreset, a shared region: three
    copies) would not fit in this machine's memory: then closed, and a
    :class:`~remoteenv.agent.errors.LimitError` with the figures."""
    each = 3 * value_nbytes(session.handshake.observation_space)
    problem = worlds_problem(
        num_envs, each, f"{label}'s observation buffers", "ask for at most {fit} worlds (num_envs) of this observation"
    )
    if problem is not None:
        session.close()
        raise LimitError(problem)
    return session


def default_layout_threads(num_envs: int, envs_per_process: int) -> int | None:
    """The physics threads the default layout asks of its sims (None: the sims'
    own default), unless the user set them for every sim (``REMOTEENV_SIM_THREADS``)."""
    if os.environ.get(SIM_THREADS_ENV, "").strip():
        return None
    return layout_threads(num_envs, envs_per_process)


__all__ = ["default_layout_threads", "open_worlds"]
