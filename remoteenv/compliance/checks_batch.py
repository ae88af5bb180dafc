"""Checks of ``reset_batch`` and ``step_batch``, for servers that offer them.

A server offers them when its handshake says so (see
:meth:`~remoteenv.compliance.handshake_check.Handshake.offered`); the others skip
these checks. Every check resets the worlds it uses first.

Runs in the checking process, an agent of the server under test (it speaks the wire itself: no sim code, no env classes).
"""

from __future__ import annotations

from typing import Any

from remoteenv.compliance.check_results import Check
from remoteenv.compliance.failures import CheckSkipped, fail_unless
from remoteenv.compliance.handshake_check import BATCH_COMMANDS, Handshake
from remoteenv.compliance.probe import Probe
from remoteenv.compliance.probe_actions import invalid_actions, neutral_action, stacked_actions
from remoteenv.compliance.values import (
    batch_obs_problem,
    infos_problem,
    is_int,
    list_problem,
    type_name,
    value_problem,
)
from remoteenv.wire.protocol import OP_RESET, OP_STEP, OP_STEP_AUTORESET, OP_STEP_RESET
from remoteenv.wire.wire_errors import INVALID_ACTION, PROTOCOL, short_repr


def _batch(p: Probe) -> Handshake:
    hs = p.handshake
    why = hs.lacks(*BATCH_COMMANDS)
    if why:
        raise CheckSkipped(why)
    return hs


def _fail_on(problem: str | None, what: str) -> None:
    fail_unless(problem is None, f"{what}: {problem}")


def _reset_all(p: Probe, hs: Handshake, seeds: list[int | None] | None = None) -> dict[str, Any]:
    worlds = list(range(hs.num_worlds))
    reply = p.ok("reset_batch", worlds=worlds, seeds=seeds, options=None)
    what = f"reset_batch of worlds {short_repr(worlds)}"
    _fail_on(batch_obs_problem(hs.observation_space, reply.get("obs"), len(worlds)), what)
    _fail_on(infos_problem(reply.get("info"), len(worlds)), what)
    return reply


def _final_problem(hs: Handshake, final: Any, n: int) -> str | None:
    if not isinstance(final, list):
        return f"final must be a list, got {type_name(final)}"
    for entry in final:
        if not (isinstance(entry, list) and len(entry) == 3):
            return f"each final entry must be [world, obs, info], got {short_repr(entry)}"
        world, obs, info = entry
        if not (is_int(world) and 0 <= world < n):
            return f"final entry names world {short_repr(world)}, expected one of 0..{n - 1}"
        problem = value_problem(hs.observation_space, obs, f"final obs of world {world}")
        if problem:
            return problem
        if not isinstance(info, dict):
            return f"final info of world {world} must be a map, got {type_name(info)}"
    return None


def _step_batch(p: Probe, hs: Handshake, ops: list[int], actions: Any) -> dict[str, Any]:
    """``step_batch`` with ``ops``; the reply checked for ``len(ops)`` worlds."""
    n = len(ops)
    reply = p.ok("step_batch", ops=ops, actions=actions)
    what = f"step_batch with ops {ops}"
    _fail_on(batch_obs_problem(hs.observation_space, reply.get("obs"), n), what)
    _fail_on(list_problem(reply.get("reward"), n, float, "reward"), what)
    _fail_on(list_problem(reply.get("terminated"), n, bool, "terminated"), what)
    _fail_on(list_problem(reply.get("truncated"), n, bool, "truncated"), what)
    _fail_on(infos_problem(reply.get("info"), n), what)
    _fail_on(_final_problem(hs, reply.get("final"), n), what)
    return reply


def _final_worlds(reply: dict[str, Any]) -> list[int]:
    return sorted(entry[0] for entry in reply["final"])


def batch_reset(p: Probe) -> str:
    hs = _batch(p)
    n = hs.num_worlds
    _reset_all(p, hs, seeds=list(range(n)))
    _reset_all(p, hs)
    last = [n - 1]
    reply = p.ok("reset_batch", worlds=last, seeds=[None], options=None)
    _fail_on(batch_obs_problem(hs.observation_space, reply.get("obs"), 1), f"reset_batch of worlds {last}")
    _fail_on(infos_problem(reply.get("info"), 1), f"reset_batch of worlds {last}")
    return f"{n} world(s)"


def batch_step(p: Probe) -> str:
    hs = _batch(p)
    n = hs.num_worlds
    space = hs.action_space
    _reset_all(p, hs, seeds=list(range(n)))
    actions = [neutral_action(space)] * n
    reply = _step_batch(p, hs, [OP_STEP] * n, stacked_actions(space, actions))
    fail_unless(
        reply["final"] == [],
        f"step_batch with ops {[OP_STEP] * n} (step only) listed final entries for worlds {_final_worlds(reply)}",
    )
    _step_batch(p, hs, [OP_STEP] * n, actions)
    _step_batch(p, hs, [OP_STEP], stacked_actions(space, actions[:1]))
    return f"{n} world(s): stacked actions, a list of actions, and a prefix of 1 world"


def batch_ops(p: Probe) -> None:
    hs = _batch(p)
    n = hs.num_worlds
    actions = stacked_actions(hs.action_space, [neutral_action(hs.action_space)] * n)
    _reset_all(p, hs)
    reply = _step_batch(p, hs, [OP_RESET] * n, actions)
    fail_unless(
        reply["reward"] == [0.0] * n
        and not any(reply["terminated"])
        and not any(reply["truncated"])
        and reply["final"] == [],
        f"ops 1 (reset) must give reward 0, not terminated, not truncated and no final entries; got "
        f"reward {short_repr(reply['reward'])}, final worlds {_final_worlds(reply)}",
    )
    reply = _step_batch(p, hs, [OP_STEP_RESET] * n, actions)
    fail_unless(
        _final_worlds(reply) == list(range(n)),
        f"ops 3 (step, then reset) must list every world in final, got worlds {_final_worlds(reply)}",
    )
    reply = _step_batch(p, hs, [OP_STEP_AUTORESET] * n, actions)
    done = [w for w in range(n) if reply["terminated"][w] or reply["truncated"][w]]
    fail_unless(
        _final_worlds(reply) == done,
        f"ops 2 (step, reset if done) must list exactly the done worlds {done} in final, got {_final_worlds(reply)}",
    )


def batch_errors(p: Probe) -> str:
    hs = _batch(p)
    n = hs.num_worlds
    space = hs.action_space
    neutral = neutral_action(space)
    _reset_all(p, hs)
    for cmd, why, args in (
        ("step_batch", "ops [9] (no such op)", {"ops": [9], "actions": stacked_actions(space, [neutral])}),
        ("step_batch", "ops [] (no worlds)", {"ops": [], "actions": []}),
        (
            "step_batch",
            f"{n + 1} ops for {n} worlds",
            {"ops": [OP_STEP] * (n + 1), "actions": stacked_actions(space, [neutral] * (n + 1))},
        ),
        ("step_batch", "ops '0' (a str)", {"ops": "0", "actions": stacked_actions(space, [neutral])}),
        ("reset_batch", f"worlds [{n}] (the server hosts {n})", {"worlds": [n], "seeds": None, "options": None}),
        ("reset_batch", "2 seeds for 1 world", {"worlds": [0], "seeds": [1, 2], "options": None}),
    ):
        p.error(cmd, [PROTOCOL], why, **args)
    bad = invalid_actions(space)
    for label, action in bad:
        p.error(
            "step_batch",
            [INVALID_ACTION],
            f"world 0's action {label} ({short_repr(action)})",
            ops=[OP_STEP] * n,
            actions=[action] + [neutral] * (n - 1),
        )
    p.still_serving("batch requests with bad arguments")
    return f"6 malformed requests and {len(bad)} invalid actions refused"


CHECKS = (
    Check("batch_reset", "reset_batch replies: stacked obs in the space, infos for each world", batch_reset),
    Check("batch_step", "step_batch replies: obs, float rewards, bool flags, infos, final", batch_step),
    Check("batch_ops", "step_batch ops 1 (reset), 2 (autoreset) and 3 (step, reset) as specified", batch_ops),
    Check("batch_errors", "malformed batch requests get 'protocol', bad actions 'invalid_action'", batch_errors),
)
