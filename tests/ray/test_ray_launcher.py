"""Sims placed on a local multi-node Ray cluster (a head and two worker nodes)."""

from __future__ import annotations

import glob
import os
import tempfile
import time

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv import OpenAIRemoteEnv, RemoteVectorEnv, SimDiedError
from remoteenv.agent.errors import LaunchError
from remoteenv.delays import Trace
from remoteenv.integrations.ray import RayLauncher
from remoteenv.wire.delays.delay_line import LockStepDelays

REACHER = "remoteenv/Reacher-v0"


def _rollout(envs, steps: int, seed: int) -> list[np.ndarray]:
    """Observations, rewards and flags of ``steps`` vector steps of seeded random actions."""
    rng = np.random.default_rng(seed)
    obs, _ = envs.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        actions = rng.uniform(-1, 1, size=envs.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, _ = envs.step(actions)
        out += [obs, reward, terminated, truncated]
    return out


def test_spread_puts_each_sim_on_its_own_node(cluster, assert_nothing_left) -> None:
    launcher = RayLauncher(strategy="SPREAD", num_cpus_per_process=1)
    envs = gym.make_vec(
        REACHER, num_envs=6, vectorization_mode="vector_entry_point", envs_per_process=2, launcher=launcher
    )
    try:
        assert isinstance(envs.unwrapped, RemoteVectorEnv)
        assert len(launcher.sims) == 3
        assert set(launcher.node_ids) == cluster.alive_node_ids()
        assert all(s.endpoint.startswith("tcp://127.0.0.1:") for s in launcher.sims)
        obs, _ = envs.reset(seed=1)
        assert obs.shape == (6, 10)
    finally:
        envs.close()
    assert_nothing_left(launcher)


def test_strict_spread_beyond_the_node_count_is_refused_clearly(cluster) -> None:
    launcher = RayLauncher(strategy="STRICT_SPREAD", num_cpus_per_process=0.5)
    with pytest.raises(LaunchError, match=r"could not place 4 x .*STRICT_SPREAD.*3 live node"):
        RemoteVectorEnv(remoteenv.scene_path("cartpole"), 4, envs_per_process=1, launcher=launcher, startup_timeout=3.0)


def test_a_label_selector_keeps_sims_on_the_labelled_node(cluster) -> None:
    launcher = RayLauncher(strategy="SPREAD", num_cpus_per_process=0.5, label_selector={"pool": "b"})
    envs = RemoteVectorEnv(remoteenv.scene_path("cartpole"), 2, envs_per_process=1, launcher=launcher)
    try:
        assert [cluster.pools.get(n) for n in launcher.node_ids] == ["b", "b"]
    finally:
        envs.close()


def test_lock_step_trajectories_equal_a_local_launch(cluster) -> None:
    local = gym.make_vec(REACHER, num_envs=4, vectorization_mode="vector_entry_point", envs_per_process=2)
    remote = gym.make_vec(
        REACHER,
        num_envs=4,
        vectorization_mode="vector_entry_point",
        envs_per_process=2,
        launcher=RayLauncher(strategy="SPREAD", num_cpus_per_process=0.5),
    )
    try:
        expected = _rollout(local, 60, seed=7)  # past the 50-step limit: autoreset included
        got = _rollout(remote, 60, seed=7)
    finally:
        local.close()
        remote.close()
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        np.testing.assert_array_equal(a, b)


def test_a_single_env_on_the_cluster_matches_a_local_one(cluster) -> None:
    scene = remoteenv.scene_path("cartpole")
    runs = []
    for launcher in (None, RayLauncher(num_cpus_per_process=0.5)):
        kwargs = {} if launcher is None else {"launcher": launcher}
        env = OpenAIRemoteEnv(scene, **kwargs)
        try:
            obs, _ = env.reset(seed=3)
            trace = [obs]
            for t in range(30):
                trace.append(env.step(t % 2)[0])
        finally:
            env.close()
        runs.append(np.array(trace))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_a_trace_of_the_documented_maximum_reaches_a_sim_on_a_worker_node(cluster, assert_nothing_left) -> None:
    """100,000 delays of up to 10,000 ticks travel to the node with the actor
    and reach the sim in a file there, removed when the sim stops. The first
    16 are short, so their actions land within the test: the ages the sim
    reports (known once each action landed) are the engine's for this trace."""
    values = np.random.default_rng(2).integers(0, 10_000, size=100_000, endpoint=True)
    values[:16] = np.random.default_rng(3).integers(0, 3, size=16, endpoint=True)
    trace = Trace(values)
    before = set(glob.glob(os.path.join(tempfile.gettempdir(), "remoteenv-ray-*")))
    launcher = RayLauncher(num_cpus_per_process=0.5, label_selector={"pool": "a"})
    env = OpenAIRemoteEnv(remoteenv.scene_path("cartpole"), action_delay=trace, launcher=launcher)
    try:
        assert launcher.node_ids[0] != cluster.head_node_id
        env.reset(seed=0)
        ages = [env.step(0)[4]["action_delay_ticks"] for _ in range(16)]
        spec = env.handshake["stepping"]["action_delay_spec"]
    finally:
        env.close()
    engine = LockStepDelays(trace)
    engine.reset(None, 0.0, None, seed=0)
    expected = []
    for _ in range(16):
        engine.apply(0)
        expected.append(engine.observe(None, 0.0)[1].action_delay_ticks)
    assert spec == trace.to_wire() and ages == expected
    assert_nothing_left(launcher)
    assert set(glob.glob(os.path.join(tempfile.gettempdir(), "remoteenv-ray-*"))) <= before


def test_real_time_runs_on_the_cluster(cluster) -> None:
    env = OpenAIRemoteEnv(
        remoteenv.scene_path("cartpole"), real_time=True, launcher=RayLauncher(num_cpus_per_process=0.5)
    )
    try:
        env.reset(seed=0)
        start = time.perf_counter()
        for _ in range(25):
            _, _, terminated, _, info = env.step(0)
            if terminated:
                env.reset()
        elapsed = time.perf_counter() - start
        assert "ticks_elapsed" in info and info["ticks_elapsed"] >= 1
        # Paced at 1x wall clock: 25 control ticks of 0.02 s take about 0.5 s.
        assert elapsed >= 25 * env.dt * 0.8
        assert env.latency_stats.steps == 25
    finally:
        env.close()


def test_a_killed_sim_is_relaunched_with_restart_on_failure(cluster, assert_nothing_left) -> None:
    launcher = RayLauncher(num_cpus_per_process=0.5)
    envs = RemoteVectorEnv(
        remoteenv.scene_path("cartpole"), 4, envs_per_process=2, launcher=launcher, restart_on_failure=True
    )
    try:
        envs.reset(seed=0)
        old = launcher.sims[1]
        launcher.kill(1)
        _, _, _, truncated, info = envs.step(np.zeros(4, dtype=np.int64))
        assert list(truncated) == [False, False, True, True]
        assert list(info["remoteenv_restarted"]) == [False, False, True, True]
        assert "SIGKILL" in str(info["remoteenv_error"][2])
        assert launcher.sims[1].pid != old.pid and launcher.sims[1].restarts == 1
        envs.step(np.zeros(4, dtype=np.int64))
    finally:
        envs.close()
    assert_nothing_left(launcher)


def test_a_killed_sim_without_restart_is_reported_promptly(cluster) -> None:
    launcher = RayLauncher(num_cpus_per_process=0.5)
    env = OpenAIRemoteEnv(remoteenv.scene_path("cartpole"), launcher=launcher, timeout=60.0)
    try:
        env.reset(seed=0)
        launcher.kill(0)
        start = time.perf_counter()
        with pytest.raises(SimDiedError, match=r"SIGKILL.*Ray node"):
            env.step(0)
        assert time.perf_counter() - start < 5.0  # long before the 60 s reply timeout
    finally:
        env.close()


def test_losing_a_node_mid_run(cluster, assert_nothing_left) -> None:
    """Two envs with a sim on every node; one worker node is killed outright.
    The env with restart_on_failure relaunches its lost sim on a surviving node
    and goes on; the other raises an error that names the lost node."""
    scene = remoteenv.scene_path("cartpole")
    surviving = RayLauncher(strategy="SPREAD", num_cpus_per_process=0.4)
    failing = RayLauncher(strategy="SPREAD", num_cpus_per_process=0.4)
    a = RemoteVectorEnv(scene, 3, envs_per_process=1, launcher=surviving, restart_on_failure=True)
    b = RemoteVectorEnv(scene, 3, envs_per_process=1, launcher=failing)
    try:
        a.reset(seed=0)
        b.reset(seed=0)
        victim = next(n for n in surviving.node_ids if n != cluster.head_node_id)
        lost = surviving.node_ids.index(victim)
        lost_node = surviving.sims[lost].node
        start = time.perf_counter()
        cluster.remove_worker(cluster.worker_node(victim))
        # The sims on the lost node may answer a few more steps before Ray
        # reports their actors gone (a crashed machine would answer none).
        zeros = np.zeros(3, dtype=np.int64)
        while time.perf_counter() - start < 60:
            _, _, _, truncated, info = a.step(zeros)
            if "remoteenv_restarted" in info and info["remoteenv_restarted"][lost]:
                break
        recovered_s = time.perf_counter() - start
        print(
            f"\nnode {lost_node} removed: sim {lost} relaunched on {surviving.sims[lost].node}; "
            f"the step that did it returned {recovered_s:.1f} s after the removal"
        )
        assert truncated[lost] and info["remoteenv_restarted"][lost]
        assert surviving.sims[lost].node_id != victim
        assert surviving.sims[lost].node_id in cluster.alive_node_ids()
        for _ in range(5):
            a.step(zeros)
        with pytest.raises(SimDiedError, match=lost_node.split(" ")[0]) as caught:
            while time.perf_counter() - start < 60:
                b.step(zeros)
        assert victim[:12] in str(caught.value)
    finally:
        a.close()
        b.close()
        cluster.restore()
    assert_nothing_left(surviving)


_DRIVER = """
import json, sys, time
import gymnasium as gym, ray, remoteenv
from remoteenv.integrations.ray import RayLauncher
ray.init(address=sys.argv[1])
launcher = RayLauncher(strategy="SPREAD", num_cpus_per_process=0.5)
envs = gym.make_vec("remoteenv/CartPole-v0", num_envs=2, vectorization_mode="vector_entry_point",
                    envs_per_process=1, launcher=launcher)
envs.reset(seed=0)
print(json.dumps({"pids": launcher.pids, "actors": [s.actor._actor_id.hex() for s in launcher.sims],
                  "group": launcher.placement_group_id}), flush=True)
time.sleep(600)
"""


def test_a_killed_agent_leaves_nothing_on_the_cluster(cluster, assert_nothing_left) -> None:
    import json
    import signal
    import subprocess
    import sys
    from types import SimpleNamespace

    driver = subprocess.Popen(
        [sys.executable, "-c", _DRIVER, cluster.cluster.address], stdout=subprocess.PIPE, text=True
    )
    try:
        line = driver.stdout.readline()
        assert line, "the driver exited before starting its sims"
        started = json.loads(line)
    finally:
        driver.send_signal(signal.SIGKILL)
        driver.wait()
        driver.stdout.close()
    # What assert_nothing_left reads of a launcher, rebuilt from the dead driver's report.
    sims = [SimpleNamespace(actor=SimpleNamespace(_actor_id=bytes.fromhex(a))) for a in started["actors"]]
    gone = SimpleNamespace(sims=sims, pids=started["pids"], placement_group_id=started["group"])
    assert_nothing_left(gone, timeout=30.0)
