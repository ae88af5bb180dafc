"""Lock-step delay models against an in-process replay, exactly.

The replay runs the same scene in this process and schedules actions and
observations by brute force from the rules in ``docs/latency.md`` (the
newest due action is in force; the newest arrived observation is returned),
with the delays drawn from the documented streams. It shares no code with
the sim's delay engine besides the specs' ``sample``.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv import RemoteVectorEnv
from remoteenv.delays import Categorical, Constant, Trace, Uniform
from remoteenv.scenes.reacher.reacher_scene import ReacherEnv
from remoteenv.wire.delays.delay_line import ACTION_STREAM, OBS_STREAM, delay_rng

STEPS = 30
DT = 0.02


def draws(spec, seed, stream, n):
    rng = delay_rng(seed, stream)
    return [int(spec.sample(rng, i)) for i in range(n)]


def arrivals(delays, in_order):
    """Arrival of item i = 1..T (index 0: the initial one, at 0): ``i + delay``, in order if asked."""
    out = [0]
    for i, d in enumerate(delays, 1):
        out.append(max(i + d, out[-1]) if in_order else i + d)
    return out


def replay(seed, actions, action_delay, obs_delay, in_order=False):
    """The documented semantics, by brute force: ``[(obs, reward, info subset)]`` per step."""
    env = ReacherEnv()
    A = arrivals(draws(action_delay, seed, ACTION_STREAM, len(actions)), in_order)
    B = arrivals(draws(obs_delay, seed, OBS_STREAM, len(actions)), in_order)
    x0, _ = env.reset(seed=seed)
    xs, times, alphas, returned = [x0], [0.0], [0], [0]
    out = []
    for n in range(1, len(actions) + 1):
        s = max(i for i in range(n + 1) if A[i] <= n)  # the newest action arrived by tick n (0: default)
        action = actions[s - 1] if s else env.default_action()
        x, reward, _, _ = env.step(action)
        xs.append(x)
        times.append(float(env.data.time))
        alphas.append(n - s)
        m = max(k for k in range(n + 1) if B[k] <= n)
        returned.append(m)
        out.append(
            (
                xs[m],
                float(reward),
                {
                    "action_delay_ticks": n - s,
                    "obs_delay_ticks": n - m,
                    "obs_sim_time": times[m],
                    "obs_action_delay_ticks": alphas[m],
                    "latency_ticks": None if s == 0 else A[s] - 1 - returned[s - 1],
                },
            )
        )
    return out


def actions_for(seed, n=STEPS):
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, size=2).astype(np.float32) for _ in range(n)]


def run_single(seed, actions, **delays):
    env = gym.make("remoteenv/Reacher-v0", max_episode_steps=max(50, len(actions) + 1), **delays)
    try:
        env.reset(seed=seed)
        return [env.step(a) for a in actions]
    finally:
        env.close()


def assert_matches(remote, expected):
    assert len(remote) == len(expected)
    for t, ((obs, reward, terminated, truncated, info), (x, r, keys)) in enumerate(zip(remote, expected), 1):
        np.testing.assert_array_equal(obs, x, err_msg=f"step {t}")
        assert reward == r, f"step {t}"
        assert not terminated and not truncated
        for key, value in keys.items():
            assert info[key] == value, f"step {t}: {key} {info[key]} != {value}"
        for key in ("applied_action", "obs_applied_action"):
            assert key in info


MODELS = {
    "constant": (Constant(2), Constant(3)),
    "uniform": (Uniform(0, 3), Uniform(0, 2)),
    "categorical": (Categorical([0, 2, 5], [0.5, 0.3, 0.2]), Categorical([1, 4])),
    "trace": (Trace([3, 0, 0, 1, 4, 2]), Trace([0, 2, 1])),
    "action only": (Uniform(1, 4), 0),
    "obs only": (0, Uniform(0, 3)),
}


@pytest.mark.parametrize("model", list(MODELS))
def test_every_delay_model_matches_the_in_process_replay_exactly(model):
    action_delay, obs_delay = MODELS[model]
    seed = 21
    actions = actions_for(seed)
    remote = run_single(seed, actions, action_delay=action_delay, obs_delay=obs_delay)
    as_spec = [Constant(v) if isinstance(v, int) else v for v in (action_delay, obs_delay)]
    assert_matches(remote, replay(seed, actions, *as_spec))


#: Bursty traces, long enough that thousands of ticks cycle through them with their overtakings.
LONG_TRACES = (
    Trace([0, 0, 1, 9, 0, 2, 0, 0, 12, 1, 0, 0, 5, 3, 0, 7, 0, 0, 0, 11, 2, 0, 1]),
    Trace([1, 0, 0, 6, 0, 2, 0, 9, 0, 0, 1, 4, 0]),
)


@pytest.mark.parametrize("rule", ["newest", "in_order"])
def test_each_delivery_rule_matches_the_replay_over_thousands_of_trace_ticks(rule):
    """Observations, rewards, alpha (now and at the returned tick), omega and the latency,
    exactly, for 2,000 ticks of Trace delays under each rule."""
    action_delay, obs_delay = LONG_TRACES
    seed = 23
    actions = actions_for(seed, 2000)
    remote = run_single(
        seed, actions, action_delay=action_delay, obs_delay=obs_delay, action_delivery=rule, obs_delivery=rule
    )
    assert_matches(remote, replay(seed, actions, action_delay, obs_delay, in_order=rule == "in_order"))


def test_batched_worlds_draw_their_own_delays_seeded_per_world():
    """Four worlds in two processes of two (step_batch): world i is the replay with seed + i."""
    action_delay, obs_delay = Uniform(0, 3), Categorical([0, 1, 3])
    seed = 40
    env = RemoteVectorEnv(
        remoteenv.scene_path("reacher"),
        num_envs=4,
        envs_per_process=2,
        action_delay=action_delay,
        obs_delay=obs_delay,
    )
    try:
        assert env.envs_per_process == 2
        env.reset(seed=seed)
        rng = np.random.default_rng(3)
        batch = [rng.uniform(-1, 1, size=(4, 2)).astype(np.float32) for _ in range(20)]
        steps = [env.step(a) for a in batch]
    finally:
        env.close()
    for w in range(4):
        expected = replay(seed + w, [a[w] for a in batch], action_delay, obs_delay)
        for t, ((obs, reward, terminated, truncated, infos), (x, r, keys)) in enumerate(zip(steps, expected), 1):
            np.testing.assert_array_equal(obs[w], x, err_msg=f"world {w} step {t}")
            assert reward[w] == r and not terminated[w] and not truncated[w]
            for key, value in keys.items():
                assert infos[key][w] == value, f"world {w} step {t}: {key}"


def test_same_seed_same_trajectory_in_two_processes_and_another_seed_differs():
    delays = {"action_delay": Uniform(0, 3), "obs_delay": Uniform(0, 2)}
    actions = actions_for(5)
    a = run_single(8, actions, **delays)
    b = run_single(8, actions, **delays)
    c = run_single(9, actions, **delays)
    for (obs_a, rew_a, *_, info_a), (obs_b, rew_b, *_, info_b) in zip(a, b):
        np.testing.assert_array_equal(obs_a, obs_b)
        assert rew_a == rew_b
        assert info_a["action_delay_ticks"] == info_b["action_delay_ticks"]
        assert info_a["obs_delay_ticks"] == info_b["obs_delay_ticks"]
    assert [i["obs_delay_ticks"] for *_, i in a] != [i["obs_delay_ticks"] for *_, i in c]


def test_a_reset_without_seed_continues_the_streams_and_a_seeded_one_repeats():
    env = gym.make("remoteenv/Reacher-v0", action_delay=Uniform(0, 5), max_episode_steps=None)
    try:
        push = np.ones(2, dtype=np.float32)
        env.reset(seed=3)
        first = [env.step(push)[4]["action_delay_ticks"] for _ in range(15)]
        env.reset()
        second = [env.step(push)[4]["action_delay_ticks"] for _ in range(15)]
        env.reset(seed=3)
        again = [env.step(push)[4]["action_delay_ticks"] for _ in range(15)]
        hs = env.unwrapped.handshake
    finally:
        env.close()
    assert first == again and first != second
    assert hs.action_delay == 5 and hs["stepping"]["action_delay_spec"] == Uniform(0, 5).to_wire()


def test_the_worked_example_of_the_docs():
    """``action_delay=2, obs_delay=1``: the table in docs/latency.md."""
    remote = run_single(0, actions_for(0, 4), action_delay=2, obs_delay=1)
    rows = [(i["action_delay_ticks"], i["obs_delay_ticks"], i["latency_ticks"]) for *_, i in remote]
    assert rows == [(1, 1, None), (2, 1, None), (2, 1, 2), (2, 1, 3)]
    assert [i["obs_action_delay_ticks"] for *_, i in remote] == [0, 1, 2, 2]
    assert [i["obs_sim_time"] for *_, i in remote] == pytest.approx([0.0, DT, 2 * DT, 3 * DT])
    assert remote[0][4]["applied_action"] is None and remote[1][4]["applied_action"] is None


def test_a_trace_of_the_documented_maximum_launches_and_is_replayed():
    """100,000 delays of up to 10,000 ticks: far too long for a command line
    (the spec reaches the sim in its delay file)."""
    values = np.random.default_rng(1).integers(0, 10_000, size=100_000, endpoint=True)
    values[:20] = np.random.default_rng(2).integers(0, 4, size=20, endpoint=True)  # these act within 20 steps
    values[-1] = 10_000
    trace = Trace(values)
    env = gym.make("remoteenv/CartPole-v0", continuous=True, action_delay=trace, max_episode_steps=None)
    try:
        env.reset(seed=0)
        hs = env.unwrapped.handshake
        ages = []
        for _ in range(20):  # the pole stands that long without a push
            _, _, terminated, _, info = env.step(np.zeros(1, dtype=np.float32))
            ages.append(info["action_delay_ticks"])
            assert not terminated
    finally:
        env.close()
    assert hs["stepping"]["action_delay_spec"] == trace.to_wire()  # every value arrived
    assert hs.action_delay == 10_000
    due = [s + int(values[s - 1]) for s in range(1, 21)]
    assert ages == [t - max([s for s in range(1, t + 1) if due[s - 1] <= t], default=0) for t in range(1, 21)]
