"""Nothing from the future: no lock-step info field tells a delay that has not elapsed.

Over 10^5 steps of random delays (the pure engine, both delivery rules,
delayed rewards, episodes that end), every value a delayed step reports is
correlated with every *undelivered* delay: at step ``t``, the delay ``d_s`` of
each action sent at ``s <= t`` whose own delay has not elapsed
(``s + d_s > t``), and the delay ``o_n`` of each observation produced at
``n <= t`` with ``n + o_n > t``. What a delayed agent may know about such a
delay is only that it has not elapsed, which says more the younger the item
is; so the delays are compared within their age ``t - s`` (or ``t - n``):
centred and scaled per age, then pooled. Without a leak every such
correlation is 0 in expectation; ``|corr| <= 0.01`` is asserted. The
``latency_ticks`` lock-step reported before (``t + d_t - 1 - m_{t-1}``, from
the delay drawn for the action just sent, which the engine keeps for
debugging as ``sent_delay_ticks``) is the control: the same statistic must
find it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from remoteenv.delays import Uniform
from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.delay_line import OBS_STREAM, LockStepDelays, delay_rng

K = 8
STEPS = 100_000
DT = 0.02
SEED = 11


def _number(value: Any) -> float:
    """An action or info value as a number (the toy actions are their step; None: -1)."""
    return -1.0 if value is None else float(value)


#: The values a delayed step reports, as numbers: every key of the reply's
#: info (timing keys included), the returned observation, reward and flag,
#: and the engine's drop count. ActionHistory's features are among them:
#: include_alpha = obs_action_delay_ticks, include_obs_delay = obs_delay_ticks,
#: include_latency = latency_ticks (None as 0); its action buffer holds the
#: agent's own actions, which no delay changes.
FIELDS: dict[str, Callable[[dict[str, Any]], float]] = {
    "action_delay_ticks": lambda r: r["info"]["action_delay_ticks"],
    "applied_action": lambda r: _number(r["info"]["applied_action"]),
    "action_took_effect": lambda r: float(r["info"]["action_took_effect"]),
    "obs_delay_ticks": lambda r: r["info"]["obs_delay_ticks"],
    "obs_sim_time": lambda r: r["info"]["obs_sim_time"],
    "obs_action_delay_ticks": lambda r: r["info"]["obs_action_delay_ticks"],
    "obs_applied_action": lambda r: _number(r["info"]["obs_applied_action"]),
    "latency_ticks": lambda r: _number(r["info"]["latency_ticks"]),
    "latency known": lambda r: float(r["info"]["latency_ticks"] is not None),
    "late": lambda r: float(r["info"]["action_delay_ticks"] > 0),
    "sim_time": lambda r: r["step"] * DT,
    "returned obs": lambda r: float(r["obs"]),
    "reward": lambda r: r["reward"],
    "terminated": lambda r: float(r["terminated"]),
    "actions dropped so far": lambda r: r["dropped"],
}


def run(rules: ChannelRules, steps: int = STEPS) -> tuple[list[dict[str, Any]], list, list]:
    """``steps`` steps of the engine; per step its report, and the (step, age, delay)
    pairs of the undelivered action and observation delays."""
    engine = LockStepDelays(Uniform(0, K), Uniform(0, K), rules)
    obs_rng = delay_rng(SEED, OBS_STREAM)  # the documented stream: one draw per tick that runs physics
    obs_draws = 0
    world = np.random.default_rng(0)  # the toy world: random rewards, episodes ending at random ticks
    rows: list[dict[str, Any]] = []
    action_pairs: list[tuple[int, int, int]] = []
    obs_pairs: list[tuple[int, int, int]] = []
    t_global = 0
    seed: int | None = SEED
    while t_global < steps:
        engine.reset(0, 0.0, None, seed=seed)
        seed = None  # later episodes continue the streams
        actions: list[tuple[int, int]] = []  # (sent, delay) whose delay has not elapsed
        observations: list[tuple[int, int]] = []
        done = False
        held = 0  # the observation tick the agent holds when sending
        while not done and t_global < steps:
            t_global += 1
            t = engine.step + 1
            engine.apply(t)
            if engine.frozen:
                _, record = engine.observe_frozen()
            else:
                terminated = bool(world.random() < 0.01)
                _, record = engine.observe(t, t * DT, float(world.normal()), terminated)
                o = int(Uniform(0, K).sample(obs_rng, obs_draws))
                obs_draws += 1
                observations.append((t, o))
            delivered = engine.deliver(0.0, False, None)
            actions.append((t, record.sent_delay_ticks))
            actions = [(s, d) for s, d in actions if s + d > t]
            observations = [(n, o) for n, o in observations if n + o > t]
            row = len(rows)
            action_pairs += [(row, t - s, d) for s, d in actions]
            obs_pairs += [(row, t - n, o) for n, o in observations]
            rows.append(
                {
                    "step": t,
                    "info": record.info(),
                    "obs": delivered.obs,
                    "reward": delivered.reward,
                    "terminated": delivered.terminated,
                    "dropped": engine.actions_dropped,
                    "old latency_ticks": t + record.sent_delay_ticks - 1 - held,
                }
            )
            held = record.obs_tick
            done = delivered.terminated
    return rows, action_pairs, obs_pairs


def within_age_corr(values: np.ndarray, pairs: list[tuple[int, int, int]]) -> float:
    """Correlation of ``values[row]`` with the delays of ``pairs``, the delays
    centred and scaled within each age (see the module docstring)."""
    p = np.asarray(pairs)
    rows, ages, delays = p[:, 0], p[:, 1], p[:, 2].astype(float)
    z = np.zeros_like(delays)
    for age in np.unique(ages):
        sel = ages == age
        sd = delays[sel].std()
        if sd > 0:
            z[sel] = (delays[sel] - delays[sel].mean()) / sd
    f = values[rows]
    if f.std() == 0:
        return 0.0
    return float(np.corrcoef(f, z)[0, 1])


RULES = {
    "newest": ChannelRules(delayed_rewards=True),
    "in_order": ChannelRules(action_delivery="in_order", obs_delivery="in_order", delayed_rewards=True),
}


@pytest.mark.parametrize("rule", list(RULES))
def test_no_reported_value_correlates_with_an_undelivered_delay(rule):
    rows, action_pairs, obs_pairs = run(RULES[rule])
    assert len(rows) == STEPS and len(action_pairs) > STEPS and len(obs_pairs) > STEPS
    found = {}
    for name, field in FIELDS.items():
        values = np.array([field(r) for r in rows], dtype=float)
        found[name] = (within_age_corr(values, action_pairs), within_age_corr(values, obs_pairs))
    print(f"\n{rule}: within-age corr with undelivered (action, observation) delays")
    for name, (ca, co) in found.items():
        print(f"  {name:24s} {ca:+.4f} {co:+.4f}")
    worst = max(found, key=lambda k: max(abs(found[k][0]), abs(found[k][1])))
    assert max(abs(c) for c in found[worst]) <= 0.01, f"{worst} leaks: {found[worst]}"
    # The control: lock-step's former latency_ticks, the delay of the action
    # just sent plus the agent's observation age, is found at once.
    old = np.array([r["old latency_ticks"] for r in rows], dtype=float)
    lag0 = [pair for pair in action_pairs if pair[1] == 0]
    pooled, newest = within_age_corr(old, action_pairs), within_age_corr(old, lag0)
    print(f"  former latency_ticks     {pooled:+.4f} (age 0 only: {newest:+.4f})")
    assert pooled > 0.1 and newest > 0.5
