"""The agent's end of the layout gate: read what a gated sim measured, then let it go on or stop it.

Runs in the agent process. A :class:`~remoteenv.agent.launch.launcher.Launcher`
given a :attr:`~remoteenv.agent.launch.launcher.Launcher.layout_gate` starts
its first sim with ``--layout-gate FILE``: the sim measures a scratch world,
writes :class:`GateFacts` to ``FILE`` and waits, before building the worlds it
will serve (:mod:`remoteenv.sim.process.layout_gate`; the file's format is in
:mod:`remoteenv.wire.protocol`, "The layout gate"). The gate reads the facts;
if they call for the layout launched, the sim is told to go on (:func:`go`),
else the launch stops (:class:`LayoutRejected`) before a world is built. The
file is a sim's word: read bounded and checked like a reply.
"""

from __future__ import annotations

import math
import os
import signal
from dataclasses import dataclass
from typing import Any

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.sim_command import StartingSim, wait_for
from remoteenv.wire.codec.frame_limits import MAX_WORLDS
from remoteenv.wire.files.file_reads import UnreadableFile, read_json

#: Largest gate file read (bytes); a well-formed one is under 200.
GATE_FILE_LIMIT = 4 << 10
#: The sim's go (its end: :data:`remoteenv.sim.process.layout_gate.GO_SIGNAL`).
GO_SIGNAL = signal.SIGUSR1


@dataclass(frozen=True)
class GateFacts:
    """What a gated sim measured of one world of its scene."""

    #: Seconds one world's whole control tick cost on one thread (None: not finite).
    cost_s: float | None
    #: Whether the scene's worlds step as one batch (stacked hooks, one ``mujoco.batch``).
    stacked_hooks: bool
    #: How many worlds' observations one batch reply carries.
    fit: int


class LayoutRejected(Exception):
    """The gate found the launched layout wrong for the scene; :attr:`facts` say why."""

    def __init__(self, facts: GateFacts) -> None:
        super().__init__(f"the layout gate turned the launch down: {facts}")
        self.facts = facts


def parse_facts(doc: Any, pid: int) -> GateFacts:
    """The :class:`GateFacts` of a gate file's JSON ``doc`` written by the sim of
    process ``pid``; ValueError saying what is wrong with it otherwise."""
    if not isinstance(doc, dict):
        raise ValueError(f"expected a JSON object, got {type(doc).__name__}")
    if doc.get("pid") != pid:
        raise ValueError(f"written by pid {str(doc.get('pid'))[:20]}, not by the sim (pid {pid})")
    cost = doc.get("world_cost_s")
    if cost is not None and (
        isinstance(cost, bool) or not isinstance(cost, (int, float)) or not math.isfinite(cost) or cost < 0
    ):
        raise ValueError(f"'world_cost_s' must be a finite number >= 0 or null, got {str(cost)[:40]}")
    stacked = doc.get("stacked_hooks")
    if not isinstance(stacked, bool):
        raise ValueError(f"'stacked_hooks' must be true or false, got {str(stacked)[:40]}")
    fit = doc.get("worlds_that_fit")
    if isinstance(fit, bool) or not isinstance(fit, int) or not 0 <= fit:
        raise ValueError(f"'worlds_that_fit' must be an int >= 0, got {str(fit)[:40]}")
    return GateFacts(None if cost is None else float(cost), stacked, min(fit, MAX_WORLDS))


def wait_facts(sim: StartingSim, path: str, timeout: float, what: str) -> GateFacts:
    """Wait until ``sim`` has written its gate file ``path`` and read it. Polls
    (:func:`~remoteenv.agent.launch.sim_command.wait_for`), never a fixed sleep. Raises
    :class:`RemoteEnvError` (kind ``"launch"``) if the process exits first, if
    ``timeout`` seconds pass or if the file is malformed; ``what`` names the
    sim's scene in the message."""

    def look() -> GateFacts | None:
        try:
            return parse_facts(read_json(path, GATE_FILE_LIMIT, what="layout gate file"), sim.pid)
        except FileNotFoundError:
            return None  # not there yet (it is written whole, by a rename)
        except (UnreadableFile, ValueError) as exc:
            raise RemoteEnvError(
                f"sim instance {sim.instance} (pid {sim.pid}) of {what} wrote a malformed layout gate "
                f"file {path}: {exc}",
                kind="launch",
                instance=sim.instance,
            ) from None

    return wait_for(sim, look, timeout, what, "measure a world")


def go(sim: StartingSim) -> None:
    """Tell a gated ``sim`` to build its worlds and serve them (a sim gone
    meanwhile is left to the wait for its ready file, which reports why)."""
    try:
        os.kill(sim.pid, GO_SIGNAL)
    except ProcessLookupError:
        pass


__all__ = ["GATE_FILE_LIMIT", "GO_SIGNAL", "GateFacts", "LayoutRejected", "go", "parse_facts", "wait_facts"]
