"""Batched steps through the local pipe's shared-memory region (``shared_batch``):
the same results as the msgpack path (with the fast lane silent or loud), used
where offered, refused off the pipe."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from equality import assert_same

import remoteenv  # noqa: F401  (registers the ids)
from remoteenv import scene_path
from remoteenv.agent.connection import shared_lane_client as shared_lane
from remoteenv.agent.connection.connect import Connection
from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.launcher import Launcher
from remoteenv.agent.vector import lean_step
from remoteenv.wire.shared_memory import doorbell


def _trajectory(env_id: str, n: int, steps: int, k: int, autoreset: str) -> list[tuple]:
    env = gym.make_vec(
        env_id,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        envs_per_process=k,
        autoreset_mode=gym.vector.AutoresetMode(autoreset),
    )
    rng = np.random.default_rng(3)
    try:
        out: list[tuple] = [env.reset(seed=7)]
        for _ in range(steps):
            if isinstance(env.single_action_space, gym.spaces.Discrete):
                actions = rng.integers(0, 2, size=n)
            else:
                actions = rng.uniform(-1, 1, size=(n, *env.single_action_space.shape)).astype(np.float32)
            out.append(env.step(actions))
        lanes = [arrays is not None for _, arrays in env._requests.lanes._lanes.values()]
        out.append(("lanes", lanes))
        return out
    finally:
        env.close()


@pytest.mark.parametrize(
    "env_id, autoreset",
    [
        ("remoteenv/Reacher-v0", "NextStep"),
        ("remoteenv/CartPole-v0", "NextStep"),
        ("remoteenv/CartPole-v0", "SameStep"),
    ],
)
def test_the_region_gives_the_results_of_the_msgpack_path(monkeypatch, env_id, autoreset):
    # 120 steps cross Reacher's 50-step limit twice and end CartPole episodes.
    shared = _trajectory(env_id, 6, 120, 3, autoreset)
    monkeypatch.setattr(shared_lane, "attach", lambda conn: None)
    plain = _trajectory(env_id, 6, 120, 3, autoreset)
    assert shared[-1] == ("lanes", [True, True]) and plain[-1] == ("lanes", [False, False])
    assert_same(shared[:-1], plain[:-1], "trajectory")


@pytest.mark.parametrize("env_id, least", [("remoteenv/Reacher-v0", 115), ("remoteenv/CartPole-v0", 75)])
def test_plain_steps_of_one_process_go_lean_with_the_usual_results(monkeypatch, env_id, least):
    posted: list[bool] = []
    post = lean_step.LeanStep.post

    def counted(self, *args):
        seq = post(self, *args)
        posted.append(seq is not None)
        return seq

    monkeypatch.setattr(lean_step.LeanStep, "post", counted)
    lean = _trajectory(env_id, 6, 120, 6, "NextStep")
    monkeypatch.setattr(lean_step.LeanStep, "post", lambda self, *args: None)
    usual = _trajectory(env_id, 6, 120, 6, "NextStep")
    # A step goes lean unless it resets a world (or is the first; the step after a reset
    # writes its plain ops again and goes lean): Reacher's worlds end together every
    # 50 steps, CartPole's one by one, often (116 and 82 steps of 120 with these seeds).
    print(f"{sum(posted)} of 120 steps went lean")
    assert len(posted) == 120 and sum(posted) >= least, posted
    assert lean[-1] == usual[-1] == ("lanes", [True])
    assert_same(lean[:-1], usual[:-1], "trajectory")


def test_only_the_launching_pipe_gets_the_region():
    with Launcher(scene_path("reacher"), worlds_per_instance=2, startup_timeout=120.0) as launcher:
        sim = launcher.sims[0]
        conn = Connection(sim.endpoint, timeout=30.0, death_check=sim.death)
        try:
            handshake = conn.request("handshake", protocol=1)
            assert "shared_batch" in handshake["commands"]
            with pytest.raises(RemoteEnvError) as info:
                conn.request("shared_batch")
            assert info.value.kind == "state" and "local pipe" in str(info.value)
            conn.request("reset_batch", worlds=[0, 1])
            with pytest.raises(RemoteEnvError) as info:
                conn.request("step_batch", ops=[0, 0], shared=True)
            assert info.value.kind == "state"
            assert sim.death() is None
        finally:
            conn.close()


def test_a_loud_doorbell_gives_the_same_results(monkeypatch):
    # Off x86-64 every request and reply of the fast lane also goes as its frame: forced here on both ends.
    monkeypatch.setenv("REMOTEENV_LOUD_DOORBELL", "1")  # the sims read it when they start
    monkeypatch.setattr(doorbell, "SILENT", False)
    made: list[bool] = []
    real_init = doorbell.Doorbell.__init__

    def recording_init(self, header, silent=None):
        real_init(self, header, silent)
        made.append(self.silent)

    monkeypatch.setattr(doorbell.Doorbell, "__init__", recording_init)
    loud = _trajectory("remoteenv/CartPole-v0", 4, 60, 2, "NextStep")
    assert made == [False, False]  # the agent's ends of both regions' lanes
    monkeypatch.setattr(shared_lane, "attach", lambda conn: None)
    plain = _trajectory("remoteenv/CartPole-v0", 4, 60, 2, "NextStep")
    assert loud[-1] == ("lanes", [True, True]) and plain[-1] == ("lanes", [False, False])
    assert_same(loud[:-1], plain[:-1], "trajectory")


def _tamper(arrays, how: str) -> None:
    """One write into a mapped region, as any process that can open it could make."""
    import os

    header = arrays.header
    if how == "huge-request-seq":
        header[doorbell.REQ_SEQ] = 2**62
    elif how == "huge-reply-seq":
        header[doorbell.REP_SEQ] = 2**62
    elif how == "random-header":
        header.view(np.uint8)[:] = np.frombuffer(os.urandom(header.nbytes), dtype=np.uint8)
    else:
        region = arrays._region
        region[:] = os.urandom(len(region))


@pytest.mark.parametrize("how", ["huge-request-seq", "huge-reply-seq", "random-header", "random-region"])
def test_a_tampered_region_is_dropped_and_the_env_keeps_stepping(how):
    """Issue 28, item 3: one write into the region used to wedge the env for good
    (every later step timed out). Now the side that finds the header off drops
    the region, the steps take msgpack, and the trajectory is the one an
    untouched env gives (no step served twice, none lost)."""
    n, k = 4, 2
    make = dict(num_envs=n, vectorization_mode="vector_entry_point", envs_per_process=k)
    tampered = gym.make_vec("remoteenv/CartPole-v0", **make)
    reference = gym.make_vec("remoteenv/CartPole-v0", **make)
    rng = np.random.default_rng(5)
    try:
        assert_same(tampered.reset(seed=11), reference.reset(seed=11), "reset")
        for step in range(30):
            if step == 5:
                lanes = tampered._requests.lanes._lanes
                regions = [arrays for _, arrays in lanes.values()]
                assert all(a is not None and a.header is not None for a in regions)
                _tamper(regions[0], how)
            actions = rng.integers(0, 2, size=n)
            if step == 5:
                with pytest.warns(RuntimeWarning, match="tampered with"):
                    got = tampered.step(actions)
            else:
                got = tampered.step(actions)
            assert_same(got, reference.step(actions), f"step {step}")
        lanes = tampered._requests.lanes._lanes
        assert [arrays is not None for _, arrays in lanes.values()] == [False, True]  # the untouched one stays
    finally:
        tampered.close()
        reference.close()
