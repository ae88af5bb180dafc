"""The two delivery rules and delayed rewards, tick by tick, against a brute-force reference.

The reference is written from the rules in ``docs/delays.md`` alone: it lists
every send and arrival time, and at each tick takes the newest arrived item
by scanning all of them. It shares no code with the engine.
"""

from __future__ import annotations

import numpy as np
import pytest

from remoteenv.delays import Trace, Uniform
from remoteenv.wire.delays.channel_rules import ChannelRules
from remoteenv.wire.delays.delay_line import DelayLine, LockStepDelays
from remoteenv.wire.wire_errors import ProtocolError

TICKS = 3000


def arrivals(delays: list[int], rule: str) -> list[int]:
    """Arrival time of item 1..T (index 0: the initial item, arrived at 0)."""
    out = [0]
    for i, d in enumerate(delays, 1):
        due = i + d
        out.append(due if rule == "newest" else max(due, out[-1]))
    return out


def reference(d: list[int], o: list[int], action_rule: str, obs_rule: str) -> list[dict[str, int | None]]:
    """Per step t = 1..T: alpha, omega, the returned tick, alpha of that tick, the latency."""
    T = len(d)
    A = np.array(arrivals(d, action_rule))
    B = np.array(arrivals(o, obs_rule))
    alpha, in_force, m = [0], [0], [0]  # index 0: the reset tick
    for t in range(1, T + 1):
        s_star = int(np.nonzero(A[: t + 1] <= t)[0].max())  # newest action arrived by tick t
        n_star = int(np.nonzero(B[: t + 1] <= t)[0].max())  # newest observation arrived by step t
        alpha.append(t - s_star)
        in_force.append(s_star)
        m.append(n_star)
    rows = []
    for t in range(1, T + 1):
        s = in_force[t]
        rows.append(
            {
                "action_delay_ticks": alpha[t],
                "obs_delay_ticks": t - m[t],
                "obs_action_delay_ticks": alpha[m[t]],
                "latency_ticks": None if s == 0 else int(A[s]) - 1 - m[s - 1],
                "acted": s,
            }
        )
    return rows


def trace(seed: int, high: int, n: int = 700) -> list[int]:
    """A bursty trace: quiet stretches and spikes up to ``high``."""
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 3, n)
    spikes = rng.random(n) < 0.15
    return [int(v) for v in np.where(spikes, rng.integers(0, high + 1, n), base)]


COMBOS = [("newest", "newest"), ("in_order", "in_order"), ("newest", "in_order"), ("in_order", "newest")]


@pytest.mark.parametrize(("action_rule", "obs_rule"), COMBOS)
def test_each_rule_matches_the_brute_force_reference_over_thousands_of_trace_ticks(action_rule, obs_rule):
    d_trace, o_trace = trace(1, 12), trace(2, 9, 500)
    engine = LockStepDelays(Trace(d_trace), Trace(o_trace), ChannelRules(action_rule, obs_rule))
    engine.reset(0, 0.0, "default", seed=0)
    records = []
    for t in range(1, TICKS + 1):
        engine.apply(t)
        records.append(engine.observe(t, float(t))[1])
    d = [d_trace[i % len(d_trace)] for i in range(TICKS)]
    o = [o_trace[i % len(o_trace)] for i in range(TICKS)]
    expected = reference(d, o, action_rule, obs_rule)
    for t, (got, want) in enumerate(zip(records, expected), 1):
        for key in ("action_delay_ticks", "obs_delay_ticks", "obs_action_delay_ticks", "latency_ticks"):
            assert getattr(got, key) == want[key], f"step {t}: {key}"
        assert got.applied_action == (want["acted"] or "default"), f"step {t}"
        if got.obs_tick == t:  # no observation delay: the returned tick's values are this tick's
            assert got.obs_action_delay_ticks == got.action_delay_ticks
            assert got.obs_applied_action == got.applied_action
    acted = {w["acted"] for w in expected} - {0}
    stats = engine.stats()
    assert stats["actions_acted"] == len(acted)
    assert stats["never_acted_fraction"] == pytest.approx(1 - len(acted) / TICKS)
    assert stats["mean_action_age_ticks"] == pytest.approx(np.mean([w["action_delay_ticks"] for w in expected]))


def test_in_order_holds_an_action_back_until_every_older_one_arrived():
    """Delays 3, 0, 0, 0: newest-due runs a2 at tick 2; in order a2 waits for a1 (tick 4)."""
    for rule, expected in (
        ("newest", ["default", "a2", "a3", "a4", "a5"]),
        ("in_order", ["default", "default", "default", "a4", "a5"]),
    ):
        engine = LockStepDelays(Trace([3, 0, 0, 0, 0]), 0, ChannelRules(action_delivery=rule))
        engine.reset("x0", 0.0, "default", seed=0)
        in_force = []
        for t in range(1, 6):
            in_force.append(engine.apply(f"a{t}")[0])
            engine.observe(f"x{t}", float(t))
        assert in_force == expected, rule
        # newest: a1 arrives at tick 4 after a2: dropped then; in order: a1..a4 all arrive at tick 4
        assert engine.actions_dropped == (1 if rule == "newest" else 3)


def test_a_drop_is_counted_when_the_overtaken_item_arrives_not_when_it_is_overtaken():
    line: DelayLine[str] = DelayLine("init")
    line.push(1, 6, "a")
    line.push(2, 3, "b")
    line.advance(3)
    assert line.dropped == 0  # at tick 3 nobody could know yet that "a" will come too late
    line.advance(6)
    assert line.dropped == 1 and line.took_effect == 1


def test_the_uniform_figures_of_the_docs():
    """docs/delays.md: Uniform(0, 16) leaves the acting action ~3.9 ticks old
    under newest-due and ~12.2 in order, with ~71 % of the actions never acting."""
    ages = {}
    for rule in ("newest", "in_order"):
        engine = LockStepDelays(Uniform(0, 16), 0, ChannelRules(action_delivery=rule))
        engine.reset(0, 0.0, None, seed=0)
        for t in range(20_000):
            engine.apply(t)
            engine.observe(t, 0.0)
        stats = engine.stats()
        ages[rule] = stats["mean_action_age_ticks"]
        assert 0.69 < stats["never_acted_fraction"] < 0.73
    assert 3.6 < ages["newest"] < 4.2 and 11.8 < ages["in_order"] < 12.6


# --- delayed rewards ----------------------------------------------------------------------------


def test_delayed_rewards_travel_with_the_observation_and_the_physics_freezes_at_termination():
    engine = LockStepDelays(0, Trace([2, 0, 3, 0, 0]), ChannelRules(delayed_rewards=True))
    engine.reset("x0", 0.0, None, seed=0)
    out = []
    for t in range(1, 9):
        engine.apply(t)
        if engine.frozen:
            engine.observe_frozen()
        else:
            engine.observe(f"x{t}", float(t), reward=float(10 * t), terminated=(t == 5), scene_info={"tick": t})
        sent = engine.deliver(-1.0, False, None)
        out.append((sent.obs, sent.reward, sent.terminated, sent.scene_info))
        if sent.terminated:
            break
    # arrivals: x1 at 3, x2 at 2, x3 at 6, x4 at 4, x5 at 5 (terminal); frozen from step 6 on
    assert out == [
        ("x0", 0.0, False, None),
        ("x2", 30.0, False, {"tick": 2}),  # x2 delivers ticks 1 and 2
        ("x2", 0.0, False, {"tick": 2}),  # x1 arrives late: dropped, its reward came with x2
        ("x4", 70.0, False, {"tick": 4}),  # ticks 3 and 4 (x3 still on its way: overtaken)
        ("x5", 50.0, True, {"tick": 5}),  # the terminal observation ends the episode
    ]
    assert sum(r for _, r, _, _ in out) == sum(10 * t for t in range(1, 6))


def test_frozen_steps_run_no_physics_until_the_terminal_observation_arrives():
    engine = LockStepDelays(1, 3, ChannelRules(delayed_rewards=True))
    engine.reset("x0", 0.0, None, seed=0)
    ticks_run, rewards, flags = [], [], []
    for t in range(1, 12):
        engine.apply(t)
        if engine.frozen:
            engine.observe_frozen()
        else:
            ticks_run.append(t)
            engine.observe(f"x{t}", float(t), reward=1.0, terminated=(t == 4))
        sent = engine.deliver(0.0, False, None)
        rewards.append(sent.reward)
        flags.append(sent.terminated)
        if sent.terminated:
            break
    assert ticks_run == [1, 2, 3, 4]  # the physics froze after the terminal tick
    assert flags == [False] * 6 + [True]  # x4 arrives at step 7
    assert rewards == [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]
    with pytest.raises(RuntimeError, match="froze"):
        engine.apply(0)
        engine.observe("x", 0.0)


def test_without_delayed_rewards_the_tick_that_ran_reports_its_reward():
    engine = LockStepDelays(0, 3)
    engine.reset("x0", 0.0, None, seed=0)
    engine.apply(1)
    engine.observe("x1", 1.0, reward=5.0, terminated=True)
    sent = engine.deliver(5.0, True, {"tick": 1})
    assert (sent.obs, sent.reward, sent.terminated, sent.scene_info) == ("x0", 5.0, True, {"tick": 1})
    assert not engine.frozen


# --- the rules' wire form -----------------------------------------------------------------------


def test_channel_rules_round_trip_and_refuse_anything_else():
    rules = ChannelRules("in_order", "newest", True)
    assert ChannelRules.from_wire(rules.to_wire()) == rules and not rules.is_default
    assert ChannelRules().is_default
    with pytest.raises(ValueError, match="action_delivery"):
        ChannelRules("fifo")
    with pytest.raises(ValueError, match="delayed_rewards"):
        ChannelRules(delayed_rewards=1)  # type: ignore[arg-type]
    for bad in ([1], {"action_delivery": "x"}, {"sneaky": 1}, {"delayed_rewards": "yes"}):
        with pytest.raises(ProtocolError):
            ChannelRules.from_wire(bad)
