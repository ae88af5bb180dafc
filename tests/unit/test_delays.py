"""Delay specs and the lock-step delay engine, checked against plain replays.

The replays below are written from the rules in ``docs/latency.md`` alone
(seeding, sampling, which action is in force, which observation is returned),
not from the engine's code, and must agree with it exactly.
"""

from __future__ import annotations

import copy
import json
import pickle

import numpy as np
import pytest

from remoteenv.delays import (
    MAX_DELAY_TICKS,
    Categorical,
    Constant,
    DelayLine,
    LockStepDelays,
    Trace,
    Uniform,
    as_delay,
    delay_from_wire,
)
from remoteenv.wire import protocol
from remoteenv.wire.delays.delay_line import ACTION_STREAM, OBS_STREAM, DelayStream
from remoteenv.wire.delays.delay_specs import MAX_VALUES
from remoteenv.wire.wire_errors import ProtocolError

SPECS = [
    Constant(0),
    Constant(3),
    Uniform(0, 3),
    Uniform(2, 2),
    Categorical([0, 1, 4], [0.25, 0.5, 0.25]),
    Categorical([1, 2]),
    Trace([0, 3, 1, 0, 0, 2, 5, 1]),
]


# --- plain replays of the documented rules -------------------------------------------------


def replay_rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(stream,))))


def replay_draws(spec, seed: int, stream: int, n: int) -> list:
    """The first n draws of a spec, from the documented sampling rules."""
    rng = replay_rng(seed, stream)
    out = []
    for i in range(n):
        if isinstance(spec, Constant):
            out.append(spec.value)
        elif isinstance(spec, Uniform) and spec.unit == "ticks":
            out.append(int(rng.integers(spec.low, spec.high + 1)))
        elif isinstance(spec, Uniform):
            out.append(spec.low + (spec.high - spec.low) * rng.random())
        elif isinstance(spec, Categorical):
            u, total = rng.random(), 0.0
            for value, p in zip(spec.values, spec.probs):
                total += p
                if u < total:
                    out.append(value)
                    break
        else:
            out.append(spec.values[i % len(spec.values)])
    return out


def replay_episode(actions, d, o, default, x0):
    """Toy physics x_t = 0.5 x_{t-1} + u_t under the delay rules; d[t], o[n] indexed from 1.

    Returns per step (returned obs, obs tick, action step in force)."""
    xs, out = [x0], []
    for t in range(1, len(actions) + 1):
        due = [s for s in range(1, t + 1) if s + d[s] <= t]
        s_star = max(due, default=0)
        u = actions[s_star - 1] if s_star else default
        xs.append(0.5 * xs[-1] + u)
        arrived = [n for n in range(0, t + 1) if n == 0 or n + o[n] <= t]
        n_star = max(arrived)
        out.append((xs[n_star], n_star, s_star))
    return out


def run_engine(engine: LockStepDelays, actions, default, x0, seed, dt=0.02):
    """The same toy physics driven through the engine."""
    engine.reset(x0, 0.0, default, seed=seed)
    x, out = x0, []
    for a in actions:
        u, _ = engine.apply(a)
        x = 0.5 * x + u
        obs, delays = engine.observe(x, engine.step * dt)
        out.append((obs, delays))
    return out


# --- the engine against the replay ------------------------------------------------------------


@pytest.mark.parametrize("obs_spec", SPECS, ids=repr)
@pytest.mark.parametrize("action_spec", SPECS, ids=repr)
def test_every_delay_model_matches_the_plain_replay_exactly(action_spec, obs_spec):
    n, seed, default, x0 = 40, 7, -0.25, 1.5
    actions = [float(v) for v in np.random.default_rng(0).uniform(-1, 1, n)]
    engine = LockStepDelays(action_spec, obs_spec)
    got = run_engine(engine, actions, default, x0, seed)
    d = [None, *replay_draws(action_spec, seed, ACTION_STREAM, n)]
    o = [None, *replay_draws(obs_spec, seed, OBS_STREAM, n)]
    expected = replay_episode(actions, d, o, default, x0)
    held = [0]  # held[s - 1]: the observation tick the agent held when sending a_s
    for t, ((obs, delays), (x, n_star, s_star)) in enumerate(zip(got, expected), 1):
        assert obs == x, f"step {t}"
        assert delays.step == t
        assert delays.obs_tick == n_star and delays.obs_delay_ticks == t - n_star
        assert delays.obs_sim_time == n_star * 0.02
        assert delays.action_step == s_star and delays.action_delay_ticks == t - s_star
        assert delays.sent_delay_ticks == d[t]
        # after the fact: the latency of the action in force, None while the default acts
        expected_latency = None if s_star == 0 else s_star + d[s_star] - 1 - held[s_star - 1]
        assert delays.latency_ticks == expected_latency
        held.append(n_star)


def test_constant_action_delay_is_the_existing_lock_step_rule():
    """action_delay=k: the default action for k ticks, then the actions k ticks late."""
    k, actions = 3, list(range(10, 20))
    engine = LockStepDelays(action_delay=k)
    engine.reset("x0", 0.0, "default", seed=0)
    applied = []
    for a in actions:
        applied.append(engine.apply(a)[0])
        _, delays = engine.observe(f"x{engine.step}", 0.0)
        assert delays.latency_ticks == (k if engine.step > k else None) and delays.obs_delay_ticks == 0
    assert applied == ["default"] * k + actions[:-k]


def test_constant_obs_delay_returns_the_observation_of_tick_t_minus_o_and_the_reset_obs_before():
    engine = LockStepDelays(obs_delay=2)
    engine.reset("x0", 0.0, None, seed=0)
    returned = []
    for t in range(1, 7):
        engine.apply(t)
        obs, delays = engine.observe(f"x{t}", t * 0.5)
        returned.append(obs)
        assert delays.obs_sim_time == max(0, t - 2) * 0.5
        assert delays.obs_delay_ticks == min(t, 2)
    assert returned == ["x0", "x0", "x1", "x2", "x3", "x4"]


# --- ordering ---------------------------------------------------------------------------------


def drive(action_delays, obs_delays=(0,), steps=6):
    engine = LockStepDelays(Trace(list(action_delays)), Trace(list(obs_delays)))
    engine.reset("x0", 0.0, "default", seed=0)
    in_force, returned = [], []
    for t in range(1, steps + 1):
        in_force.append(engine.apply(f"a{t}")[0])
        returned.append(engine.observe(f"x{t}", float(t))[0])
    return engine, in_force, returned


def test_a_newer_action_due_earlier_drops_the_older_one():
    # a1 due at tick 4, a2 at tick 2: a1 would override a2 later, so it is dropped.
    engine, in_force, _ = drive([3, 0, 0, 0, 0, 0])
    assert in_force == ["default", "a2", "a3", "a4", "a5", "a6"]
    assert engine.actions_dropped == 1


def test_a_newer_action_due_at_the_same_tick_wins():
    engine, in_force, _ = drive([2, 1, 5, 5, 5, 5])
    assert in_force == ["default", "default", "a2", "a2", "a2", "a2"]
    assert engine.actions_dropped == 1


def test_an_action_is_held_until_a_newer_one_is_due():
    engine, in_force, _ = drive([0, 2, 2, 2, 2, 2])
    assert in_force == ["a1", "a1", "a1", "a2", "a3", "a4"]
    assert engine.actions_dropped == 0


def test_observations_never_go_back_in_time():
    # x2 (delay 3) would arrive at step 5, after x3 (delay 0): x3 overtakes it.
    _, _, returned = drive([0], [0, 3, 0, 0, 0, 0])
    assert returned == ["x1", "x1", "x3", "x4", "x5", "x6"]


def test_reset_drops_everything_in_flight_and_restores_the_default():
    engine = LockStepDelays(action_delay=2, obs_delay=2)
    engine.reset("x0", 0.0, "default", seed=0)
    for t in range(1, 4):
        engine.apply(f"a{t}")
        engine.observe(f"x{t}", float(t))
    engine.reset("y0", 10.0, "default2")
    assert engine.apply("b1") == ("default2", 0)
    obs, delays = engine.observe("y1", 10.5)
    assert obs == "y0" and delays.obs_sim_time == 10.0 and delays.step == 1


def test_delay_line_counts_items_overtaken_within_one_advance():
    line: DelayLine[str] = DelayLine("init")
    line.push(1, 3, "a")
    line.push(2, 4, "b")
    assert line.in_flight == 2
    assert line.advance(5) == ("b", 2)
    assert line.dropped == 1 and line.in_flight == 0


def test_delay_line_refuses_items_out_of_order_and_time_going_back():
    line: DelayLine[str] = DelayLine("init")
    line.push(2, 2, "a")
    with pytest.raises(ValueError, match="in order"):
        line.push(2, 5, "b")
    with pytest.raises(ValueError, match="before it is sent"):
        line.push(3, 1, "c")
    line.advance(4)
    with pytest.raises(ValueError, match="cannot go back"):
        line.advance(3)


def test_engine_refuses_calls_out_of_order_and_delays_in_seconds():
    engine = LockStepDelays(1, 1)
    with pytest.raises(RuntimeError, match="before reset"):
        engine.apply(0)
    engine.reset(0, 0.0, 0, seed=0)
    with pytest.raises(RuntimeError, match="without apply"):
        engine.observe(0, 0.0)
    engine.apply(0)
    with pytest.raises(RuntimeError, match="observe first"):
        engine.apply(0)
    with pytest.raises(ValueError, match="ticks"):
        LockStepDelays(Constant(0.01, unit="s"))


# --- seeding ----------------------------------------------------------------------------------


def delays_of(engine: LockStepDelays, seeds, steps=15):
    out = []
    for seed in seeds:
        engine.reset(0, 0.0, 0, seed=seed)
        for t in range(steps):
            engine.apply(t)
            out.append(engine.observe(t, 0.0)[1])
    return out


def test_same_seed_same_delays_other_seed_other_delays():
    a = delays_of(LockStepDelays(Uniform(0, 4), Uniform(0, 4)), [3])
    b = delays_of(LockStepDelays(Uniform(0, 4), Uniform(0, 4)), [3])
    c = delays_of(LockStepDelays(Uniform(0, 4), Uniform(0, 4)), [4])
    assert a == b
    assert [x.sent_delay_ticks for x in a] != [x.sent_delay_ticks for x in c]


def test_a_reset_without_seed_continues_the_streams_and_a_seeded_one_restarts_them():
    spec = Uniform(0, 9)
    engine = LockStepDelays(spec)
    runs = delays_of(engine, [5, None, 5], steps=10)
    sent = [x.sent_delay_ticks for x in runs]
    assert sent[:20] == replay_draws(spec, 5, ACTION_STREAM, 20)
    assert sent[20:] == sent[:10]


def test_a_trace_wraps_around_and_rewinds_on_a_seeded_reset():
    engine = LockStepDelays(Trace([1, 2, 3]))
    sent = [x.sent_delay_ticks for x in delays_of(engine, [0, None, 0], steps=4)]
    assert sent == [1, 2, 3, 1] + [2, 3, 1, 2] + [1, 2, 3, 1]


def test_the_two_directions_draw_from_separate_streams():
    """Changing the action delay model leaves the observation delays unchanged."""
    a = delays_of(LockStepDelays(Uniform(0, 3), Uniform(0, 3)), [9])
    b = delays_of(LockStepDelays(Constant(0), Uniform(0, 3)), [9])
    assert [x.obs_delay_ticks for x in a] == [x.obs_delay_ticks for x in b]
    stream = DelayStream(Uniform(0, 1000), ACTION_STREAM)
    stream.seed(9)
    other = DelayStream(Uniform(0, 1000), OBS_STREAM)
    other.seed(9)
    assert [stream.draw() for _ in range(5)] != [other.draw() for _ in range(5)]


# --- specs: sampling, validation, wire ---------------------------------------------------------


@pytest.mark.parametrize(
    "spec",
    [*SPECS, Uniform(0.01, 0.05, unit="s"), Constant(0.1, unit="s"), Categorical([0.0, 0.5], [0.75, 0.25], unit="s")],
    ids=repr,
)
def test_sampling_follows_the_documented_rule(spec):
    stream = DelayStream(spec, 1)
    stream.seed(123)
    assert [stream.draw() for _ in range(50)] == replay_draws(spec, 123, 1, 50)


def test_categorical_never_draws_a_value_of_probability_zero():
    spec = Categorical([0, 7, 2, 9], [0.5, 0.0, 0.5, 0.0])
    rng = np.random.default_rng(0)
    assert {spec.sample(rng, i) for i in range(2000)} == {0, 2}
    assert spec.max == 2


def test_ticks_are_ints_and_seconds_are_floats():
    rng = np.random.default_rng(0)
    assert all(type(s.sample(rng, 0)) is int for s in SPECS)
    assert type(Uniform(0, 1, unit="s").sample(rng, 0)) is float


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: Constant(-1), "within 0"),
        (lambda: Constant(MAX_DELAY_TICKS + 1), "within 0"),
        (lambda: Constant(True), "must be a number"),
        (lambda: Constant(2.5), "whole number of ticks.*unit='s'"),
        (lambda: Constant("3"), "whole number of ticks"),
        (lambda: Constant(float("nan"), unit="s"), "within 0"),
        (lambda: Constant(1, unit="ms"), "unit must be one of"),
        (lambda: Uniform(3, 1), "low <= high"),
        (lambda: Categorical([], []), "1..100000"),
        (lambda: Categorical([1, 2], [1.0]), "one probability per value"),
        (lambda: Categorical([1, 2], [1.5, -0.5]), r"probs\[0\] must be within 0..1"),
        (lambda: Categorical([1, 2], [0.5, float("nan")]), r"probs\[1\]"),
        (lambda: Categorical([1, 2], [0.5, 0.4]), "sum to 1"),
        (lambda: Categorical([1, 2], "ab"), "sequence of numbers"),
        (lambda: Trace([]), "1..100000"),
        (lambda: Trace(np.zeros((2, 2), dtype=int)), "one-dimensional"),
        (lambda: Trace([1, -2]), r"Trace values\[1\] must be within"),
        (lambda: Trace([0] * (MAX_VALUES + 1)), "1..100000"),
        (lambda: Trace.from_seconds([0.1], dt=0), "dt must be a positive"),
    ],
    ids=lambda x: x if isinstance(x, str) else "",
)
def test_invalid_specs_are_refused_with_a_clear_message(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_specs_are_immutable_values():
    assert Uniform(0, 3) == Uniform(0, 3) and hash(Uniform(0, 3)) == hash(Uniform(0, 3))
    assert Uniform(0, 3) != Uniform(0, 3, unit="s") and Constant(1) != Trace([1])
    assert Categorical([1, 2]) == Categorical([1, 2], [0.5, 0.5])
    with pytest.raises(AttributeError, match="immutable"):
        Constant(1).value = 2  # type: ignore[misc]
    assert "Trace([0, 0, 0, 0, 0, 0, 0, 0, ...] (500 values)" in repr(Trace([0] * 500))
    for spec in SPECS:  # specs travel inside env kwargs: copies and pickles (e.g. to Ray) keep them
        assert pickle.loads(pickle.dumps(spec)) == spec and copy.deepcopy(spec) == spec


def test_as_delay_turns_a_number_into_a_constant():
    assert as_delay(2) == Constant(2)
    assert as_delay(np.int64(4)) == Constant(4)
    assert as_delay(0.25, unit="s") == Constant(0.25, unit="s")
    spec = Uniform(0, 2)
    assert as_delay(spec) is spec
    with pytest.raises(ValueError, match="expected a delay in s"):
        as_delay(spec, unit="s")
    with pytest.raises(ValueError, match="whole number of ticks"):
        as_delay(0.5)


def test_max_and_is_zero():
    assert [s.max for s in SPECS] == [0, 3, 3, 2, 4, 2, 5]
    assert Constant(0).is_zero and Trace([0, 0]).is_zero and not Uniform(0, 1).is_zero
    assert LockStepDelays(0, Constant(0)).is_zero and not LockStepDelays(0, 1).is_zero


@pytest.mark.parametrize("spec", [*SPECS, Uniform(0.01, 0.05, unit="s"), Trace([0.5, 0.25], unit="s")], ids=repr)
def test_wire_form_round_trips_through_msgpack(spec):
    desc = protocol.unpack(protocol.pack({"delay": spec.to_wire()}))["delay"]
    back = delay_from_wire(desc)
    assert back == spec and type(back) is type(spec)
    a, b = DelayStream(spec, 2), DelayStream(back, 2)
    a.seed(1)
    b.seed(1)
    assert [a.draw() for _ in range(20)] == [b.draw() for _ in range(20)]


@pytest.mark.parametrize(
    "desc, message",
    [
        ([1, 2], "must be a map"),
        ({"kind": "normal", "unit": "ticks", "value": 1}, "unknown delay kind"),
        ({"kind": 3, "unit": "ticks"}, "unknown delay kind"),
        ({"kind": "constant", "unit": "ticks"}, "has keys"),
        ({"kind": "constant", "unit": "ticks", "value": 1, "extra": 0}, "has keys"),
        ({"kind": "constant", "unit": "minutes", "value": 1}, "unit must be one of"),
        ({"kind": "constant", "unit": "ticks", "value": True}, "must be a number"),
        ({"kind": "constant", "unit": "ticks", "value": "1"}, "whole number"),
        ({"kind": "constant", "unit": "ticks", "value": 1.0}, "whole number"),
        ({"kind": "constant", "unit": "ticks", "value": 2**70}, "within 0"),
        ({"kind": "uniform", "unit": "s", "low": 1.0, "high": 0.5}, "low <= high"),
        ({"kind": "categorical", "unit": "ticks", "values": [1], "probs": 1.0}, "must be a list"),
        ({"kind": "categorical", "unit": "ticks", "values": [1, 2], "probs": [0.9, 0.9]}, "sum to 1"),
        ({"kind": "trace", "unit": "ticks", "values": {"a": 1}}, "must be a list"),
        ({"kind": "trace", "unit": "ticks", "values": [[1]]}, "whole number"),
        ({"kind": "trace", "unit": "ticks", "values": [0] * (MAX_VALUES + 1)}, "more than"),
    ],
    ids=lambda x: x if isinstance(x, str) else "",
)
def test_from_wire_refuses_anything_off_spec(desc, message):
    with pytest.raises(ProtocolError, match=message) as info:
        delay_from_wire(desc)
    assert len(str(info.value)) < 400


def test_from_wire_messages_stay_short_for_huge_input():
    huge = {"kind": "trace", "unit": "ticks", "values": ["x" * 10**6]}
    with pytest.raises(ProtocolError) as info:
        delay_from_wire(huge)
    assert len(str(info.value)) < 400
    many_keys = {f"k{i}": i for i in range(10_000)}
    with pytest.raises(ProtocolError) as info:
        delay_from_wire({"kind": "constant", **many_keys})
    assert len(str(info.value)) < 400


# --- traces from files ------------------------------------------------------------------------


def test_trace_reads_text_json_and_npy_files(tmp_path):
    text = tmp_path / "delays.txt"
    text.write_text("# recorded delays\n1, 2 3\n\n0  # idle\n")
    assert Trace(text).values == (1, 2, 3, 0)
    js = tmp_path / "delays.json"
    js.write_text(json.dumps([0.01, 0.02]))
    assert Trace(str(js), unit="s").values == (0.01, 0.02)
    npy = tmp_path / "delays.npy"
    np.save(npy, np.array([4.0, 0.0, 2.0]))
    assert Trace(npy).values == (4, 0, 2)


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("a.txt", "1 2 x3", "line 1: 'x3' is not a number"),
        ("a.txt", "1 2.5", "whole number of ticks"),
        ("a.json", '{"delays": [1]}', "must hold a list"),
        ("a.json", "[1, ", "cannot read"),
        ("a.npy", np.array([1.5]), "fractional"),
        ("a.npy", np.array([[1, 2]]), "one-dimensional"),
        ("a.npy", np.array([None, 1], dtype=object), "cannot read"),
        ("missing.txt", None, "cannot read"),
    ],
)
def test_bad_trace_files_are_refused_naming_the_file(tmp_path, name, content, message):
    path = tmp_path / name
    if isinstance(content, str):
        path.write_text(content)
    elif content is not None:
        np.save(path, content, allow_pickle=True)
    with pytest.raises(ValueError, match=message) as info:
        Trace(path)
    assert name in str(info.value) or "line 1" not in message


def test_trace_from_seconds_rounds_up_to_whole_ticks():
    assert Trace.from_seconds([0.0, 0.02, 0.021, 0.05, 0.06], dt=0.02).values == (0, 1, 2, 3, 3)
