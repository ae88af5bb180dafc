"""The exact twin with real sims: a real-time run, saved and replayed from the
file, is bit-identical in every episode, whatever the machine's timing did.

Exactness does not depend on timing (the recording says at which substep
each action took effect), so these assertions hold on a loaded machine too.
"""

from __future__ import annotations

import os
import signal
import time

import gymnasium as gym
import numpy as np
import pytest

import remoteenv  # noqa: F401
from remoteenv.controllers import CartpoleHoldPredictor, cartpole_continuous
from remoteenv.latency.twin import (
    LatencyRecorder,
    LatencyRecorderVector,
    compare_real_time_and_replay,
    first_difference,
    load_recording,
    make_twin,
)
from remoteenv.latency.twin.compare import replay_episode

ENV_ID = "remoteenv/CartPole-v0"
KWARGS = {"continuous": True}


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
@pytest.mark.parametrize("name", ["lqr", "predictor"])
def test_a_real_time_run_replayed_from_its_files_is_bit_identical(tmp_path, mode, name):
    policy = cartpole_continuous if name == "lqr" else CartpoleHoldPredictor(3)
    result = compare_real_time_and_replay(
        policy,
        ENV_ID,
        KWARGS,
        think_ticks=(0.0, 3.0),
        episodes=2,
        seed=11,
        real_time_mode=mode,
        max_episode_steps=40,
        recording_dir=tmp_path,
    )
    assert len(result["recording_files"]) == 2
    assert [row["first_difference"] for row in result["episodes"]] == [None, None]
    assert result["identical"] == result["total"] == 2
    assert result["real_time"] == result["replay"]  # returns, steps and endings
    # Real time summed the ticks each step lasted; with U(0, 3) ticks of thinking some steps lasted several.
    assert result["ticks"] > result["steps"] == 80


def test_a_twin_whose_policy_acts_otherwise_is_caught_at_its_first_different_step(tmp_path):
    path = tmp_path / "ep.json"
    env = LatencyRecorder(gym.make(ENV_ID, real_time=True, max_episode_steps=20, **KWARGS))
    try:
        obs, _ = env.reset(seed=2)
        for _ in range(20):
            obs, *_ = env.step(cartpole_continuous(obs))
    finally:
        env.close()
    env.save(path)
    episode, env_id = load_recording(path)
    assert env_id == ENV_ID and episode.steps == 20 and episode.truncated

    def nudged(obs: np.ndarray) -> np.ndarray:  # the LQR, a little off from the 6th step on
        nudged.calls += 1  # type: ignore[attr-defined]
        return cartpole_continuous(obs) + (0.05 if nudged.calls > 5 else 0.0)  # type: ignore[attr-defined]

    nudged.calls = 0  # type: ignore[attr-defined]
    replay = replay_episode(nudged, ENV_ID, episode, KWARGS, max_episode_steps=20)
    diff = first_difference(episode, replay)
    assert diff is not None and diff["step"] == 6 and "obs" in diff["differs"]


def test_pauses_and_an_emulated_link_replay_exactly_and_a_restart_is_refused(tmp_path):
    env = LatencyRecorder(
        gym.make(ENV_ID, real_time=True, link_delay=0.004, max_episode_steps=15, restart_on_failure=True, **KWARGS)
    )
    try:
        obs, _ = env.reset(seed=8)
        for j in range(15):
            if j == 5:
                with env.unwrapped.paused():  # type: ignore[attr-defined]
                    time.sleep(0.05)
            time.sleep(0.01)
            obs, *_ = env.step(cartpole_continuous(obs))
        assert env.episodes[-1].unreplayable is None
        replay = replay_episode(cartpole_continuous, ENV_ID, env.episodes[-1], KWARGS, max_episode_steps=15)
        assert first_difference(env.episodes[-1], replay) is None

        obs, _ = env.reset(seed=9)
        env.step(cartpole_continuous(obs))
        os.kill(env.unwrapped.pid, signal.SIGKILL)  # type: ignore[attr-defined]
        *_, truncated, info = env.step(cartpole_continuous(obs))
        assert truncated and info["remoteenv_restarted"]
    finally:
        env.close()
    lost = env.episodes[-1]
    assert "restarted at step 2" in str(lost.unreplayable)
    with pytest.raises(ValueError, match="cannot be replayed exactly: the sim was restarted"):
        make_twin(ENV_ID, lost, **KWARGS)


def test_each_world_of_a_real_time_vector_env_replays_exactly():
    envs = LatencyRecorderVector(
        gym.make_vec(
            ENV_ID,
            num_envs=2,
            vectorization_mode="vector_entry_point",
            real_time=True,
            real_time_mode="fixed_step",
            max_episode_steps=6,
            **KWARGS,
        )
    )
    try:
        obs, _ = envs.reset(seed=5)
        for _ in range(13):  # 6 steps, an autoreset step, 6 steps
            time.sleep(0.01)
            obs, *_ = envs.step(np.stack([cartpole_continuous(o) for o in obs]))
    finally:
        envs.close()
    for w, episodes in enumerate(envs.episodes):
        assert [(e.seed, e.resets_after_seed, e.steps, e.mode) for e in episodes] == [
            (5 + w, 0, 6, "fixed_step"),
            (5 + w, 1, 6, "fixed_step"),
        ]
    second = envs.episodes[1][1]  # world 1's episode after an unseeded autoreset
    replay = replay_episode(cartpole_continuous, ENV_ID, second, KWARGS, max_episode_steps=6)
    assert first_difference(second, replay) is None


def test_a_policy_that_reads_link_delay_s_replays_exactly_from_the_file_alone(tmp_path):
    """The twin is built from the recording alone (no kwargs) and reports the recorded link delays."""
    from remoteenv.delays import Uniform

    link = Uniform(0.001, 0.012, unit="s")

    def policy(obs: np.ndarray, info: dict) -> np.ndarray:
        return cartpole_continuous(obs) + 20.0 * float(info.get("link_delay_s", 0.0))

    def play(env, obs, steps):
        digests, rewards, info = [], [], {}
        for _ in range(steps):
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            digests.append(obs), rewards.append(float(reward))
            if terminated or truncated:
                break
        return digests, rewards, info

    env = LatencyRecorder(gym.make(ENV_ID, real_time=True, link_delay=link, max_episode_steps=25, **KWARGS))
    try:
        obs, _ = env.reset(seed=21)
        real_obs, real_rewards, last = play(env, obs, 25)
        assert "link_delay_s" in last and 0.001 <= last["link_delay_s"] <= 0.012
    finally:
        env.close()
    path = env.save(tmp_path / "linked.json")
    episode, _ = load_recording(path)
    assert episode.env is not None and episode.env.max_episode_steps == 25 and episode.link_delays is not None
    twin = make_twin(ENV_ID, path)  # nothing but the file
    try:
        assert twin.unwrapped.handshake["stepping"]["link_delay_spec"] == link.to_wire()
        obs, _ = twin.reset_to_start()
        twin_obs, twin_rewards, twin_last = play(twin, obs, 30)
    finally:
        twin.close()
    assert twin_rewards == real_rewards and twin.truncated and len(twin_obs) == 25
    assert all(np.array_equal(a, b) for a, b in zip(real_obs, twin_obs))
    assert twin_last["link_delay_s"] == last["link_delay_s"]
    with pytest.raises(ValueError, match="continuous=False contradicts"):
        make_twin(ENV_ID, path, continuous=False)


def test_link_delay_s_appears_only_with_an_emulated_link():
    env = gym.make(ENV_ID, real_time=True, **KWARGS)
    try:
        obs, _ = env.reset(seed=0)
        *_, info = env.step(cartpole_continuous(obs))
    finally:
        env.close()
    assert "link_delay_s" not in info and "latency_s" in info
