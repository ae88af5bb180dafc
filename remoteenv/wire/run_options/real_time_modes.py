"""The real-time regimes' names, and the replay schedule a reset may carry.

Shared by both sides. A real-time sim runs one regime
(``real_time_mode``, see ``docs/real-time.md``):

- ``"elastic"`` (the default): an action takes effect at the first physics
  substep after it arrives; the reply is sent at the end of the first
  control tick in which it was in force.
- ``"fixed_step"`` (rtgym's regime): an action takes effect at the first
  control-tick boundary after it arrives, and the reply is sent at that
  boundary (the step's observation is the one of that boundary).

Replay (the exact twin of a recorded real-time episode, see
``docs/latency-twin.md``): a ``reset`` whose options hold the key
:data:`REPLAY_OPTION` makes a real-time world replay that episode without a
clock. The key's value is a map ``{"mode": str, "action_substeps": [int,
...]}``: the regime the episode was recorded in (it must be the sim's) and,
for step ``j`` of the episode, the physics substep (counted from the reset,
0-based) at which its action took effect, or for an action that never took
effect the substep at which the episode ended; with an emulated link, also
``"link_delays": [float, ...]``, each step's recorded ``link_delay_s`` (wall
seconds), which the replayed step reports again (a sim without an emulated
link refuses them). The key is removed before the
scene sees the options. Each step is then answered at once, as the
real-time world would have answered it had the action arrived just before
that substep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

ELASTIC = "elastic"
FIXED_STEP = "fixed_step"
#: The real-time regimes, the default first.
REAL_TIME_MODES = (ELASTIC, FIXED_STEP)

#: The reset-options key that carries a replay schedule.
REPLAY_OPTION = "remoteenv_replay"
#: Most steps one replayed episode may have.
MAX_REPLAY_STEPS = 100_000
#: Largest substep index a replay schedule may name (2**31 - 1: far beyond any episode).
MAX_REPLAY_SUBSTEP = 2**31 - 1
#: Most control ticks one replayed step may run (the work one ~100-byte request
#: may cause: 20 s of simulated time at dt 0.02, a real-time step whose agent
#: stalled that long). A recorded step that lasted longer is not replayable.
MAX_REPLAY_STEP_TICKS = 1_000
#: Most unseeded resets an exact twin repeats to reach a recorded episode's start.
MAX_REPLAY_RESETS = 10_000
#: Largest emulated link delay a replay schedule may carry (wall seconds).
MAX_REPLAY_LINK_DELAY_S = 3600.0


@dataclass(frozen=True)
class ReplaySchedule:
    """What a replayed episode's reset carries: per step, the substep its action
    took effect at, and with an emulated link, the link delay it reported
    (wall seconds; None: no emulated link recorded)."""

    action_substeps: list[int]
    link_delays: list[float] | None = None


def check_real_time_mode(mode: Any) -> str:
    """``mode`` if it names a regime; else a ValueError listing them."""
    if not isinstance(mode, str) or mode not in REAL_TIME_MODES:
        raise ValueError(f"real_time_mode must be one of {REAL_TIME_MODES}, got {str(mode)[:40]!r}")
    return mode


def replay_options(
    options: dict[str, Any] | None, mode: str, action_substeps: list[int], link_delays: list[float] | None = None
) -> dict[str, Any]:
    """``options`` (None: none) with the replay schedule added (agent side);
    ``link_delays``: each step's recorded ``link_delay_s`` (None: no emulated link)."""
    desc: dict[str, Any] = {"mode": mode, "action_substeps": list(action_substeps)}
    if link_delays is not None:
        desc["link_delays"] = [float(d) for d in link_delays]
    return {**(options or {}), REPLAY_OPTION: desc}


def split_replay(options: dict[str, Any] | None, mode: str) -> tuple[dict[str, Any] | None, list[int] | None]:
    """:func:`split_replay_schedule` with the schedule's substeps alone."""
    rest, schedule = split_replay_schedule(options, mode)
    return rest, None if schedule is None else schedule.action_substeps


def split_replay_schedule(
    options: dict[str, Any] | None, mode: str
) -> tuple[dict[str, Any] | None, ReplaySchedule | None]:
    """A reset's options without the replay key (None if nothing else was
    there), and the schedule it carried (None: no replay). Raises ValueError
    for a malformed schedule or one recorded in another regime than ``mode``
    (the message never echoes more than a few characters of the input)."""
    if not options or REPLAY_OPTION not in options:
        return options, None
    rest = {k: v for k, v in options.items() if k != REPLAY_OPTION}
    desc = options[REPLAY_OPTION]
    if not isinstance(desc, dict) or not {"mode", "action_substeps"} <= set(desc) <= _SCHEDULE_KEYS:
        raise ValueError(
            f"reset option {REPLAY_OPTION!r} must be a map with exactly 'mode' and 'action_substeps' (and optionally 'link_delays')"
        )
    if desc["mode"] != mode:
        raise ValueError(
            f"this replay was recorded with real_time_mode={str(desc['mode'])[:20]!r}, but this sim runs "
            f"{mode!r}: launch the twin with the recording's mode"
        )
    substeps = desc["action_substeps"]
    if not isinstance(substeps, list) or not 1 <= len(substeps) <= MAX_REPLAY_STEPS:
        raise ValueError(f"a replay's action_substeps must be a list of 1..{MAX_REPLAY_STEPS} ints")
    previous = 0
    for s in substeps:
        if isinstance(s, bool) or not isinstance(s, int) or not previous <= s <= MAX_REPLAY_SUBSTEP:
            raise ValueError(
                "a replay's action_substeps must be non-decreasing ints in "
                f"0..{MAX_REPLAY_SUBSTEP}, got {str(s)[:20]!r} after {previous}"
            )
        previous = s
    link = desc.get("link_delays")
    if link is not None:
        if not isinstance(link, list) or len(link) != len(substeps):
            raise ValueError("a replay's link_delays must be a list with one delay per step")
        for d in link:
            ok = isinstance(d, (int, float)) and not isinstance(d, bool) and math.isfinite(d)
            if not ok or not 0.0 <= d <= MAX_REPLAY_LINK_DELAY_S:
                raise ValueError(
                    f"a replay's link_delays must be seconds in 0..{MAX_REPLAY_LINK_DELAY_S:g}, got {str(d)[:20]!r}"
                )
        link = [float(d) for d in link]
    return (rest or None), ReplaySchedule(substeps, link)


_SCHEDULE_KEYS = {"mode", "action_substeps", "link_delays"}


__all__ = [
    "ELASTIC",
    "FIXED_STEP",
    "MAX_REPLAY_LINK_DELAY_S",
    "MAX_REPLAY_RESETS",
    "MAX_REPLAY_STEPS",
    "MAX_REPLAY_STEP_TICKS",
    "MAX_REPLAY_SUBSTEP",
    "REAL_TIME_MODES",
    "REPLAY_OPTION",
    "ReplaySchedule",
    "check_real_time_mode",
    "replay_options",
    "split_replay",
    "split_replay_schedule",
]
