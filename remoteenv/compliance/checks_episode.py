"""Checks of the single-world commands: reset, step, render, timing, pause, close.

Values are judged against the spaces the handshake advertised. Worlds are
addressed one by one (the first :data:`MAX_WORLDS` of them).

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

import time
from typing import Any

from remoteenv.compliance.check_results import Check
from remoteenv.compliance.failures import CheckFailed, CheckSkipped, fail_unless
from remoteenv.compliance.handshake_check import Handshake
from remoteenv.compliance.probe import Probe
from remoteenv.compliance.probe_actions import invalid_actions, neutral_action
from remoteenv.compliance.values import (
    frame_problem,
    is_int,
    is_number,
    reset_reply_problem,
    step_reply_problem,
    type_name,
)
from remoteenv.wire.wire_errors import INVALID_ACTION, PROTOCOL, STATE, short_repr

#: Worlds each check addresses at most (a server may host many).
MAX_WORLDS = 8
#: Steps per world in the ``step`` check.
STEPS = 3


def _worlds(hs: Handshake) -> range:
    return range(min(hs.num_worlds, MAX_WORLDS))


def _reset(p: Probe, world: int | None, seed: int | None) -> dict[str, Any]:
    args: dict[str, Any] = {"seed": seed, "options": None}
    if world is not None:
        args["world"] = world
    reply = p.ok("reset", **args)
    where = "world 0 (by default)" if world is None else f"world {world}"
    problem = reset_reply_problem(p.handshake.observation_space, reply, f"reset of {where}")
    fail_unless(problem is None, str(problem))
    return reply


def step_before_reset(p: Probe) -> None:
    hs = p.handshake
    world = hs.num_worlds - 1
    reply = p.call("step", world=world, action=neutral_action(hs.action_space))
    if reply["ok"]:
        raise CheckSkipped(
            f"world {world} had been reset before this check (the server is not fresh); "
            "run the checks on a fresh server to try a step before reset"
        )
    kind = reply["error"]["kind"]
    fail_unless(kind == STATE, f"a step before reset on world {world} got error kind {kind!r}, expected 'state'")
    if "driven by another connection" in str(reply["error"].get("message")):  # the reference sims' words
        raise CheckSkipped(
            f"world {world} had been reset by another connection, which drives it (the server is not fresh); "
            "run the checks on a fresh server to try a step before reset"
        )
    p.still_serving("a step before reset")


def reset(p: Probe) -> str:
    hs = p.handshake
    for world in _worlds(hs):
        _reset(p, world, seed=world)
    _reset(p, None, seed=None)
    return f"{len(_worlds(hs))} world(s)"


def step(p: Probe) -> str:
    hs = p.handshake
    action = neutral_action(hs.action_space)
    for world in _worlds(hs):
        _reset(p, world, seed=world)
        for i in range(STEPS):
            reply = p.ok("step", world=world, action=action)
            problem = step_reply_problem(hs.observation_space, reply, f"step {i + 1} of world {world}")
            fail_unless(problem is None, str(problem))
            if reply["terminated"] or reply["truncated"]:
                _reset(p, world, seed=None)
    _reset(p, 0, seed=0)
    reply = p.ok("step", action=action)
    problem = step_reply_problem(hs.observation_space, reply, "step of world 0 (by default)")
    fail_unless(problem is None, str(problem))
    return f"{STEPS} steps in each of {len(_worlds(hs))} world(s)"


def invalid_action(p: Probe) -> str:
    hs = p.handshake
    _reset(p, 0, seed=0)
    cases = invalid_actions(hs.action_space)
    for label, action in cases:
        p.error(
            "step",
            [INVALID_ACTION],
            f"an action that is {label} ({short_repr(action)}) for {hs.action_space}",
            world=0,
            action=action,
        )
    p.ok("step", world=0, action=neutral_action(hs.action_space))
    return f"{len(cases)} invalid actions refused, then a valid step"


def bad_arguments(p: Probe) -> None:
    hs = p.handshake
    n = hs.num_worlds
    action = neutral_action(hs.action_space)
    _reset(p, 0, seed=0)
    for cmd, why, args in (
        ("reset", f"world {n} (the server hosts {n})", {"world": n, "seed": None, "options": None}),
        ("reset", "world -1", {"world": -1, "seed": None, "options": None}),
        ("reset", "world '0' (a str)", {"world": "0", "seed": None, "options": None}),
        ("reset", "seed 'zero' (a str)", {"world": 0, "seed": "zero", "options": None}),
        ("reset", "options [1] (a list)", {"world": 0, "seed": None, "options": [1]}),
        ("step", f"world {n} (the server hosts {n})", {"world": n, "action": action}),
        ("render", f"world {n} (the server hosts {n})", {"world": n}),
    ):
        p.error(cmd, [PROTOCOL], why, **args)
    p.still_serving("requests with bad arguments")


def render(p: Probe) -> str:
    _reset(p, 0, seed=0)
    reply = p.ok("render", world=0)
    fail_unless("frame" in reply, "the render reply has no 'frame' (the spec allows an array or nil)")
    frame = reply["frame"]
    if frame is None:
        return "frame nil"
    problem = frame_problem(frame)
    fail_unless(problem is None, str(problem))
    return f"frame {frame.shape[0]}x{frame.shape[1]}"


_SUMMARY_KEYS = ("count", "mean", "p50", "p99", "max")


def _timing_problem(entry: Any, world: int) -> str | None:
    if not isinstance(entry, dict):
        return f"timing of world {world} must be a map, got {type_name(entry)}"
    for key in ("pacing_error_s", "apply_delay_s"):
        summary = entry.get(key)
        if not (
            isinstance(summary, dict)
            and all(is_number(summary.get(k)) for k in _SUMMARY_KEYS)
            and is_int(summary["count"])
        ):
            return (
                f"timing of world {world}: {key} must map {list(_SUMMARY_KEYS)} to numbers, got {short_repr(summary)}"
            )
    for key, test in (("overruns", is_int), ("substeps", is_int), ("period_s", is_number)):
        if not test(entry.get(key)):
            return f"timing of world {world}: {key} must be a number, got {short_repr(entry.get(key))}"
    return None


def timing(p: Probe) -> str:
    hs = p.handshake
    why = hs.lacks("timing")
    if why:
        raise CheckSkipped(why)
    reply = p.ok("timing", clear=False)
    worlds = reply.get("worlds")
    if not (isinstance(worlds, list) and len(worlds) == hs.num_worlds):
        raise CheckFailed(f"timing worlds must be a list of {hs.num_worlds} maps, got {short_repr(worlds)}")
    for world, entry in enumerate(worlds):
        problem = _timing_problem(entry, world)
        fail_unless(problem is None, str(problem))
    return f"{len(worlds)} world(s)"


def pause(p: Probe) -> str:
    """``pause`` stops the clocks (sim time stands still), ``resume`` restarts them."""
    hs = p.handshake
    why = hs.lacks("pause", "resume")
    if why:
        raise CheckSkipped(why)

    def sim_times(reply: dict[str, Any], cmd: str) -> list[Any]:
        times = reply.get("sim_time")
        ok = isinstance(times, list) and len(times) == hs.num_worlds and all(is_number(t) for t in times)
        fail_unless(ok, f"{cmd} sim_time must be a list of {hs.num_worlds} numbers, got {short_repr(times)}")
        return times  # type: ignore[return-value]

    # In real time only the connection driving the worlds may pause them: take them over.
    for world in range(hs.num_worlds):
        reply = p.call("reset", world=world, seed=0, options=None)
        if not reply["ok"] and reply["error"].get("kind") == STATE:
            raise CheckSkipped(f"world {world} is driven by another connection: {reply['error'].get('message')}")
        fail_unless(reply["ok"], f"reset of world {world} failed: {short_repr(reply.get('error'))}")
    paused = sim_times(p.ok("pause"), "pause")
    time.sleep(0.05)
    again = sim_times(p.ok("pause"), "pause")
    fail_unless(again == paused, f"sim time moved while paused: {short_repr(paused)} then {short_repr(again)}")
    reply = p.ok("resume")
    fail_unless(sim_times(reply, "resume") == paused, "resume reports a sim time other than the paused one")
    fail_unless(
        is_number(reply.get("paused_s")) and reply["paused_s"] >= 0.05,
        f"resume paused_s must be the paused wall seconds (>= 0.05 here), got {short_repr(reply.get('paused_s'))}",
    )
    unpaused = p.ok("resume").get("paused_s")
    fail_unless(unpaused == 0.0, f"resuming an unpaused server must report paused_s 0.0, got {short_repr(unpaused)}")
    return f"sim time held over {reply['paused_s']:.3f} s"


def close(p: Probe) -> str:
    if not p.target.allow_close:
        raise CheckSkipped("closing stops the server; allow it with --allow-close (allow_close = True)")
    version = p.handshake.protocol
    # Only the connection driving the worlds may stop the server: take them over first.
    for world in range(p.handshake.num_worlds):
        reply = p.call("reset", world=world, seed=0, options=None)
        if not reply["ok"] and reply["error"].get("kind") == STATE:
            raise CheckSkipped(f"world {world} is driven by another connection: {reply['error'].get('message')}")
        fail_unless(reply["ok"], f"reset of world {world} failed: {short_repr(reply.get('error'))}")
    p.ok("close")
    death = p.target.death_check
    if death is None:
        p.send("handshake", protocol=version)
        p.silent(min(p.timeout, 2.0), "from a server that was closed")
        return "no reply after close"
    deadline = p.deadline()
    while death() is None:
        if time.monotonic() > deadline:
            raise CheckFailed(
                f"the server process still runs {p.timeout:g} s after 'close' (the spec says it then exits)"
            )
        time.sleep(0.05)
    return "the server process exited"


CHECKS = (
    Check("step_before_reset", "a step on a fresh world gets a 'state' error", step_before_reset),
    Check("reset", "reset replies: obs in the observation space, info a map", reset),
    Check("step", "step replies: obs in the space, float reward, bool flags, info map", step),
    Check("invalid_action", "actions outside the action space get an 'invalid_action' error", invalid_action),
    Check("bad_arguments", "out-of-range worlds and ill-typed seed/options get a 'protocol' error", bad_arguments),
    Check("render", "render replies with a uint8 H x W x 3 frame or nil", render),
    Check("timing", "timing replies with per-world pacing figures (real-time servers)", timing),
    Check("pause", "pause holds sim time, resume restarts it (real-time servers that offer them)", pause),
)

#: Last of all: it stops the server.
CLOSE = Check("close", "close is answered, then the server exits (only with allow_close)", close)
