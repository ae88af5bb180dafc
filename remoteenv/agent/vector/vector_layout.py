"""How a vector env's worlds are laid out over sim processes, and whether the
sims can host that layout.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.sim_group import SimLayout
from remoteenv.wire.messages.handshake import Handshake

#: A world whose whole control tick costs its sim more than this (wall seconds
#: on one thread through its per-world hooks, the handshake's
#: ``world_cost_s``) is costly: an image rendered each tick, not tens of
#: microseconds of physics and Python. Measured (``world_cost.step_cost``,
#: medians of 5 runs, the quiet 2-CPU machine): Reacher 110 us, the hexapod
#: 150 us; the camera CartPole at 64x64 2467 us, a CartPole rendering 64x64
#: in its own hook 1816 us. The bound sits between the two groups, about 3x
#: from the dearest cheap world and the cheapest rendering one.
COSTLY_WORLD_S = 500e-6
#: Fewest worlds per physics thread of the default layout's one process: a
#: thread for fewer costs more hand-off than the physics it takes (on the
#: 2-CPU machine 8 worlds on two threads stepped 1.04x as fast as on one, 4
#: worlds alike).
WORLDS_PER_THREAD = 4


def default_envs_per_process(num_envs: int, world_cost_s: float | None = None, stacked_hooks: bool = True) -> int:
    """K when ``envs_per_process`` is not given.

    Costly worlds (``world_cost_s`` above :data:`COSTLY_WORLD_S`, e.g. camera
    observations: a process renders its worlds one after the other on one
    CPU, while the physics of a batch runs on threads): one process per CPU,
    ``ceil(N / cpu_count)`` worlds each (8 worlds of 64x64 pixels on 2 CPUs:
    2 processes of 4; 16: 2 of 8). Measured side by side on the quiet 2-CPU
    machine (``bench --pixels --pixels-k``, 3 alternating rounds of 2 s,
    medians): 8 worlds stepped at 2652 steps/s with K = 4 against 2136 with
    K = 1 and 1262 with K = 8 (742, 883 and 805 us CPU per step); 16 worlds
    at 2333 with K = 8 against 1965 with K = 4 and 1660 with K = 2. Beside a
    CPU hog more processes take a larger share of the contended CPUs (8
    worlds: K = 1 1399, K = 4 1315): pass ``envs_per_process`` when other
    work shares the machine.

    Otherwise, where :func:`default_physics_threads` gives the worlds two
    threads or more (N >= 9 on 2 CPUs) and the scene steps its
    worlds as one batch (``stacked_hooks``, as the first sim's handshake says;
    a scene whose Python runs per world keeps a process per CPU): every world
    in one process, its physics on those threads (``mujoco.batch``'s, the GIL
    released), its hooks stacked in one call. Measured side by side on the
    2-CPU machine (Reacher, rounds taking turns in one process, 2026-11-28,
    docs/performance.md "One process, its physics on threads"), against a
    process per CPU pinned to it: a PPO-shaped training loop 1.08x as fast
    at N = 12, 1.04x at N = 16, 1.05x at N = 32, 1.00x at N = 64; plain
    stepping 1.28x, 1.08x, 1.01x, 1.03x; beside one CPU hog, which a pinned
    sim waits behind, training 2.4x and plain stepping 4.3x as fast at N = 16.

    Otherwise at least 8 worlds per process,
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
    cpus = max(1, os.cpu_count() or 1)
    if world_cost_s is not None and world_cost_s > COSTLY_WORLD_S:
        return max(1, -(-num_envs // cpus))
    if default_physics_threads(num_envs, world_cost_s, stacked_hooks) > 1:
        return num_envs
    return _per_cpu_layout(num_envs, cpus)


def default_physics_threads(num_envs: int, world_cost_s: float | None = None, stacked_hooks: bool = True) -> int:
    """Physics threads of each sim process of the default layout of ``num_envs``
    worlds (see :func:`default_envs_per_process`): for cheap worlds stepped as
    one batch that a process per CPU would spread over two processes or more,
    one per :data:`WORLDS_PER_THREAD` worlds, at most one per CPU; else 1 (one
    process of one thread already, costly worlds: a process per CPU renders
    them, and scenes whose Python runs per world, ``stacked_hooks`` False: a
    process per CPU runs it)."""
    if not stacked_hooks or (world_cost_s is not None and world_cost_s > COSTLY_WORLD_S):
        return 1
    cpus = max(1, os.cpu_count() or 1)
    if num_envs <= _per_cpu_layout(num_envs, cpus):
        return 1
    return max(1, min(cpus, num_envs // WORLDS_PER_THREAD))


def _per_cpu_layout(num_envs: int, cpus: int) -> int:
    """K of a process per CPU, at least 8 worlds each (capped at ``num_envs``)."""
    return min(num_envs, max(8, -(-num_envs // cpus)))


def layout_threads(num_envs: int, envs_per_process: int) -> int | None:
    """The physics threads the default layout gives processes of ``envs_per_process``
    of ``num_envs`` worlds: :func:`default_physics_threads` for the one process
    of cheap worlds, else None (the sims' own default)."""
    if envs_per_process < num_envs:
        return None
    threads = default_physics_threads(num_envs)
    return threads if threads > 1 else None


def cost_may_change_layout(num_envs: int) -> bool:
    """Whether what one world costs can change :func:`default_envs_per_process`
    for ``num_envs`` worlds (on this machine's CPUs), for a scene that steps
    its worlds as one batch: if not, nobody need measure it."""
    return default_envs_per_process(num_envs, None) != default_envs_per_process(num_envs, float("inf"))


def plan_layout(
    num_envs: int,
    envs_per_process: int | None,
    real_time: bool,
    layout: SimLayout | None,
    *,
    max_episode_steps: int | None = None,
    batch_size: int | None = None,
) -> tuple[int, bool]:
    """``(K, real_time)`` of a vector env of ``num_envs`` worlds: a group whose
    ``layout`` is fixed already (e.g. attached sims) is driven as it is (its
    world count must be ``num_envs``); else K is ``envs_per_process`` or
    :func:`default_envs_per_process` of a scene whose Python runs per world
    (a process per CPU; 1 in real time): the layout that holds for every
    scene, and the cheapest to start and relaunch from (a costly world's
    sims start as they stay; the default layout's cheap worlds stepped as
    one batch start in one process once a probe's handshake says so, or move
    there once the first handshake does, see
    :func:`~remoteenv.agent.vector.vector_launch.open_worlds`). K is not capped at N
    here. The env's other counts, ``max_episode_steps`` and ``batch_size``, are
    checked too. A ValueError says which argument to change."""
    if layout is not None:  # e.g. attached sims: drive them as they are
        envs_per_process, real_time = layout.worlds_per_instance, layout.real_time
        if num_envs != layout.num_worlds:
            raise ValueError(
                f"{layout.source} serves {layout.num_worlds} worlds; pass num_envs={layout.num_worlds} (got {num_envs})"
            )
    if envs_per_process is None:
        envs_per_process = 1 if real_time else default_envs_per_process(num_envs, stacked_hooks=False)
    if envs_per_process < 1:
        raise ValueError(f"envs_per_process must be >= 1, got {envs_per_process}")
    if real_time and envs_per_process != 1:
        raise ValueError(
            f"real_time=True needs envs_per_process=1 (got {envs_per_process}): each sim "
            "process runs one paced clock, so it can host only one world"
        )
    if max_episode_steps is not None and max_episode_steps < 1:
        raise ValueError(f"max_episode_steps must be >= 1 or None, got {max_episode_steps}")
    if batch_size is not None and not 1 <= batch_size <= num_envs:
        raise ValueError(f"batch_size must be in [1, num_envs={num_envs}], got {batch_size}")
    return envs_per_process, real_time


def world_slices(num_envs: int, per_process: int) -> list[tuple[int, int]]:
    """``(first, end)`` world indices of each process, ``per_process`` worlds each (the last may have fewer)."""
    num_procs = -(-num_envs // per_process)
    return [(p * per_process, min((p + 1) * per_process, num_envs)) for p in range(num_procs)]


def check_sims(handshakes: Sequence[Handshake], slices: Sequence[tuple[int, int]], batches: bool) -> None:
    """Refuse sims that cannot serve the worlds ``slices[p]`` of each process
    (e.g. a server other than the reference one, named in a launch-info file),
    or whose spaces differ from the first sim's (the env's);
    ``batches``: the env drives several worlds per process with ``step_batch``."""
    first = handshakes[0] if handshakes else None
    for hs, (lo, hi) in zip(handshakes, slices):
        assert first is not None
        if hs.observation_space != first.observation_space or hs.action_space != first.action_space:
            raise RemoteEnvError(
                f"sim instance {hs.instance} declares spaces {hs.observation_space} / {hs.action_space}, "
                f"unlike sim instance {first.instance} ({first.observation_space} / {first.action_space}); "
                "one vector env drives sims of one scene",
                kind="protocol",
                instance=hs.instance,
            )
        if hi - lo > hs.num_worlds:
            problem = f"hosts {hs.num_worlds} world(s), not {hi - lo}"
        elif batches and not hs.offers("step_batch"):
            problem = "does not answer step_batch, which drives several worlds per process"
        else:
            continue
        raise RemoteEnvError(
            f"sim instance {hs.instance} {problem}; drive it with envs_per_process=1 "
            f"or with sims that host {hi - lo} worlds each",
            kind="protocol",
            instance=hs.instance,
        )


__all__ = [
    "COSTLY_WORLD_S",
    "check_sims",
    "cost_may_change_layout",
    "default_envs_per_process",
    "default_physics_threads",
    "layout_threads",
    "plan_layout",
    "world_slices",
]
