"""A real-time run and its twins, with real sims: the recorder writes a
loadable plain trace and the rounded lock-step twin's ticks follow it
exactly; the example replays its recordings in the exact twin, identical in
every episode (tests/integration/test_exact_twin.py tests the exact twin itself).
"""

from __future__ import annotations

import importlib.util
import json
import os
import time

import gymnasium as gym
import numpy as np

import remoteenv  # noqa: F401
from remoteenv.controllers import cartpole_continuous
from remoteenv.delays import Trace
from remoteenv.latency.twin import LatencyRecorder, LatencyRecorderVector, decision_ticks, load_recording, make_twin

ENV_ID = "remoteenv/CartPole-v0"
EXAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "real_time_twin.py")
STEPS = 25


def record_real_time(seed: int) -> tuple[LatencyRecorder, list[np.ndarray], list[dict]]:
    """One real-time episode of the LQR, thinking U(0, 2.5) ticks of wall time per step."""
    env = LatencyRecorder(gym.make(ENV_ID, continuous=True, real_time=True, max_episode_steps=STEPS))
    rng = np.random.default_rng(seed)
    actions, infos = [], []
    try:
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            actions.append(cartpole_continuous(obs))
            time.sleep(rng.uniform(0.0, 2.5) * env.unwrapped.dt)
            obs, _, terminated, truncated, info = env.step(actions[-1])
            infos.append(info)
            done = terminated or truncated
    finally:
        env.close()
    return env, actions, infos


def in_force(values: list[int], actions_per_tick: list[np.ndarray], tick: int) -> np.ndarray | None:
    """docs/latency.md's rule, by brute force: during tick ``tick`` (from 1) the
    action in force is the newest one sent at a tick ``t`` with ``t + values[t - 1] <= tick``."""
    due = [t for t in range(1, tick + 1) if t + values[t - 1] <= tick]
    return actions_per_tick[max(due) - 1] if due else None


def test_the_twin_replays_the_recorded_ticks_exactly(tmp_path):
    recorder, actions, real_infos = record_real_time(seed=3)
    (episode,) = recorder.episodes
    assert episode.steps == len(actions) and episode.truncated  # the LQR balances at these latencies
    path = recorder.save_trace(tmp_path / "episode.trace.txt")
    trace = Trace(path)  # a plain trace file (save() writes the exact twin's recording)
    assert trace == episode.trace() and len(trace.values) == episode.ticks
    assert decision_ticks(trace.values) == episode.ticks_elapsed == [i["ticks_elapsed"] for i in real_infos]

    # The recorded actions, open loop: the twin's ticks depend on the trace alone.
    twin = make_twin(ENV_ID, path, max_episode_steps=STEPS, continuous=True)
    values = list(trace.values)
    per_tick: list[np.ndarray] = []
    ticks: list[dict] = []
    try:
        twin.reset(seed=3)
        for j, (action, real) in enumerate(zip(actions, real_infos)):
            _, reward, terminated, truncated, info = twin.step(action)
            assert not terminated and info["ticks_elapsed"] == real["ticks_elapsed"] == len(twin.last_ticks)
            assert reward == float(real["ticks_elapsed"])  # +1 per tick, summed as real time sums it
            # The reply structure: the agent sees the state at the same sim time as in real time.
            assert info["sim_time"] == real["sim_time"]
            assert truncated == (j == len(actions) - 1)
            per_tick += [action] * len(twin.last_ticks)
            ticks += twin.last_ticks
    finally:
        twin.close()
    assert len(ticks) == episode.ticks
    for n, tick in enumerate(ticks, start=1):
        # the sim drew the trace's own values: the action in force is as old as they say
        due = [t for t in range(1, n + 1) if t + values[t - 1] <= n]
        assert tick["action_delay_ticks"] == n - max(due, default=0)
        expected = in_force(values, per_tick, n)
        if expected is None:
            assert tick["applied_action"] is None
        else:
            np.testing.assert_array_equal(tick["applied_action"], expected)
    # Each action the twin applies starts at the tick boundary nearest to where real time applied it.
    start = 0
    for hold, real in zip(episode.ticks_elapsed, real_infos):
        due = start + values[start] + 1  # the tick (from 1) its copies are due
        overtaken = start + hold < len(values) and due >= start + hold + 1 + values[start + hold]
        if not overtaken:
            assert abs(real["action_sim_time"] - (due - 1) * twin.unwrapped.dt) <= twin.unwrapped.dt / 2 + 1e-9
        start += hold


def test_the_example_runs_and_writes_its_comparison(tmp_path):
    spec = importlib.util.spec_from_file_location("real_time_twin", EXAMPLE)
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    out = tmp_path / "twin.json"
    argv = ["--episodes", "2", "--max-steps", "8", "--think", "0,2", "--json", str(out)]
    example.main([*argv, "--recording-dir", str(tmp_path / "recordings")])
    report = json.loads(out.read_text())
    # The exact twin: every episode of both controllers in both regimes is identical.
    assert report["identical"] == report["total"] == 8 and report["steps"] == 8 * 8
    for mode in ("elastic", "fixed_step"):
        for policy in ("lqr", "predictor"):
            rows = report["results"][mode][policy]
            assert [row["first_difference"] for row in rows] == [None, None]
            assert [row["twin_return"] for row in rows] == [row["return"] for row in rows]
            for e in range(2):
                assert load_recording(tmp_path / "recordings" / mode / policy / f"episode-{e}.json")[0].steps == 8


def test_each_world_of_a_real_time_vector_env_is_recorded_and_its_twin_starts_where_it_did():
    envs = LatencyRecorderVector(
        gym.make_vec(
            ENV_ID,
            num_envs=2,
            vectorization_mode="vector_entry_point",
            continuous=True,
            real_time=True,
            max_episode_steps=4,
        )
    )
    starts: list[list[np.ndarray]] = [[], []]
    try:
        obs, _ = envs.reset(seed=5)
        for w in range(2):
            starts[w].append(obs[w])
        restarting = np.zeros(2, dtype=bool)
        for _ in range(10):  # 4 steps, an autoreset step, 4 steps, an autoreset step
            obs, _, terminated, truncated, _ = envs.step(np.stack([cartpole_continuous(o) for o in obs]))
            for w in np.flatnonzero(restarting):
                starts[w].append(obs[w])
            restarting = np.logical_or(terminated, truncated)
    finally:
        envs.close()
    for w, episodes in enumerate(envs.episodes):
        assert [(e.seed, e.resets_after_seed, e.steps, e.truncated) for e in episodes] == [
            (5 + w, 0, 4, True),
            (5 + w, 1, 4, True),
        ]
        assert all(sum(e.ticks_elapsed) == len(e.values()) >= 4 for e in episodes)
    # The second episode of world 1 began after an unseeded reset: its twin gets there the same way.
    twin = make_twin(ENV_ID, envs.episodes[1][1].trace(), continuous=True)
    try:
        first, _ = twin.reset(seed=6)
        second, _ = twin.reset()
    finally:
        twin.close()
    np.testing.assert_array_equal(first, starts[1][0])
    np.testing.assert_array_equal(second, starts[1][1])
