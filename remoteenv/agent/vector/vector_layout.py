"""How a vector env's worlds are laid out over sim processes, and whether the
sims can host that layout.

Runs in the agent process (:class:`remoteenv.RemoteVectorEnv`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire.handshake import Handshake


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


__all__ = ["check_sims", "default_envs_per_process"]
