"""What the default layout learnt of a scene's worlds, remembered for the rest of this agent process.

Runs in the agent process. The default layout places a vector env's worlds
from what a sim's handshake says of them (a probe's, or the first launch's:
one world's measured cost,
whether the scene steps its worlds as one batch, how many observations one
reply carries; see :func:`~remoteenv.agent.vector.vector_launch.open_worlds`);
when that differs from the first guess, the sims are closed and started
again in the better layout. A later vector env of the same scene file (not
changed since: same size and modification time), with the same scene
arguments and render mode, starts in the layout learnt, without the
relaunch and without measuring again; its handshake is still read, and a
scene that says otherwise is placed again as the first time.

Nothing is written anywhere: the memory is this process's, and at most
:data:`MAX_SCENES` scenes are kept (the oldest goes first).
"""

from __future__ import annotations

import json
import os
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: Scenes remembered at once (argument sets of a scene count apart).
MAX_SCENES = 64


@dataclass(frozen=True)
class WorldFacts:
    """What a handshake said of one world of a scene."""

    #: Seconds one world's whole control tick costs (measured in the sim; None: not measured).
    cost_s: float | None
    #: Whether the scene steps its worlds as one batch (None: the sim did not say).
    stacked_hooks: bool | None
    #: How many worlds' observations one batch reply carries.
    fit: int


_facts: OrderedDict[tuple[Any, ...], WorldFacts] = OrderedDict()


def scene_key(scene: str, env_kwargs: Mapping[str, Any], render_mode: str | None) -> tuple[Any, ...] | None:
    """The key a scene's facts are remembered under, or None if there is none
    (the file cannot be read, or its arguments are not JSON)."""
    try:
        stat = os.stat(scene)
        arguments = json.dumps(env_kwargs, sort_keys=True, allow_nan=True)
    except (OSError, TypeError, ValueError):
        return None
    return (os.path.realpath(scene), stat.st_size, stat.st_mtime_ns, arguments, render_mode)


def recall(key: tuple[Any, ...] | None) -> WorldFacts | None:
    """The facts remembered under ``key`` (None: none)."""
    if key is None:
        return None
    return _facts.get(key)


def remember(key: tuple[Any, ...] | None, facts: WorldFacts) -> None:
    """Remember ``facts`` under ``key`` (nothing if ``key`` is None), forgetting the oldest beyond :data:`MAX_SCENES`."""
    if key is None:
        return
    _facts[key] = facts
    _facts.move_to_end(key)
    while len(_facts) > MAX_SCENES:
        _facts.popitem(last=False)


def forget_all() -> None:
    """Forget every scene (the next vector env of each measures again)."""
    _facts.clear()


__all__ = ["MAX_SCENES", "WorldFacts", "forget_all", "recall", "remember", "scene_key"]
