"""Bad actions and bad requests: a ValueError on the agent side, a typed error
from the sim, and a sim that keeps serving."""

from __future__ import annotations

import numpy as np
import pytest

from remoteenv import Launcher, OpenAIRemoteEnv, RemoteEnvError, scene_path
from remoteenv.agent.connection.connect import Connection
from remoteenv.protocol import PROTOCOL_VERSION


@pytest.fixture(scope="module")
def continuous_env():
    env = OpenAIRemoteEnv(scene_path("cartpole"), continuous=True, startup_timeout=120.0)
    env.reset(seed=0)
    yield env
    env.close()


@pytest.fixture(scope="module")
def discrete_env():
    env = OpenAIRemoteEnv(scene_path("cartpole"), startup_timeout=120.0)
    env.reset(seed=0)
    yield env
    env.close()


@pytest.fixture(scope="module")
def raw():
    """A continuous CartPole sim and a bare connection that skips agent-side checks."""
    launcher = Launcher(scene_path("cartpole"), env_kwargs={"continuous": True}, startup_timeout=120.0)
    sim = launcher.sims[0]
    conn = Connection(sim.endpoint, timeout=30.0, death_check=sim.death)
    conn.request("handshake", protocol=PROTOCOL_VERSION)
    conn.request("reset", seed=0)
    yield conn, sim
    conn.close()
    launcher.close()


@pytest.mark.parametrize(
    "action, words",
    [
        (np.array([0.1, 0.2], dtype=np.float32), ["shape (2,)", "Box"]),
        (np.zeros((1, 1), dtype=np.float32), ["shape (1, 1)", "Box"]),
        (np.array([np.nan], dtype=np.float32), ["NaN", "Box"]),
        (np.array([1.5], dtype=np.float32), ["outside", "Box", "1.5"]),
        (np.array([-np.inf]), ["outside", "Box"]),
        (np.array(["a"]), ["dtype <U1", "Box"]),
        ("left", ["'left'", "Box"]),
        (None, ["None", "Box"]),
    ],
)
def test_box_action_rejected_on_agent_side(continuous_env, action, words):
    with pytest.raises(ValueError) as info:
        continuous_env.step(action)
    for w in words:
        assert w in str(info.value), str(info.value)
    assert not isinstance(info.value, RemoteEnvError)  # never left the agent
    continuous_env.step(np.array([0.0], dtype=np.float32))  # still fine


@pytest.mark.parametrize("action", [2, -1, 1.5, True, "1", None, np.array([0, 1])])
def test_discrete_action_rejected_on_agent_side(discrete_env, action):
    with pytest.raises(ValueError) as info:
        discrete_env.step(action)
    assert "Discrete(2)" in str(info.value)
    assert discrete_env.step(np.int64(1))[1] == 1.0


@pytest.mark.parametrize(
    "action",
    [
        np.array([np.nan], dtype=np.float32),
        np.array([2.0], dtype=np.float32),
        np.array([0.1, 0.1], dtype=np.float32),
        np.array([[0.1]], dtype=np.float32),
        np.array([1000], dtype=np.int16),
        "left",
        [0.1, "x"],
        None,
        {"a": 1},
    ],
)
def test_sim_validates_actions_too(raw, action):
    conn, sim = raw
    with pytest.raises(RemoteEnvError) as info:
        conn.request("step", action=action)
    assert info.value.kind == "invalid_action", str(info.value)
    assert "Box" in str(info.value)
    assert sim.death() is None
    reply = conn.request("step", action=np.array([0.0], dtype=np.float32))
    assert reply["ok"] and reply["obs"].shape == (4,)


def test_sim_accepts_a_castable_dtype(raw):
    conn, _ = raw
    assert conn.request("step", action=np.array([0.25], dtype=np.float64))["ok"]


def test_protocol_version_mismatch_names_both_versions(raw):
    conn, _ = raw
    with pytest.raises(RemoteEnvError) as info:
        conn.request("handshake", protocol=PROTOCOL_VERSION + 41)
    assert info.value.kind == "protocol"
    text = str(info.value)
    assert f"agent speaks {PROTOCOL_VERSION + 41}" in text and f"speaks {PROTOCOL_VERSION}" in text


@pytest.mark.parametrize(
    "cmd, args, kind",
    [
        ("fly", {}, "protocol"),
        ("step", {"world": 3, "action": np.zeros(1, np.float32)}, "protocol"),
        ("step", {"world": True, "action": np.zeros(1, np.float32)}, "protocol"),
        ("reset", {"seed": -4}, "protocol"),
        ("reset", {"seed": "abc"}, "protocol"),
        ("reset", {"options": [1, 2]}, "protocol"),
        ("reset", {"options": {"low": "x"}}, "scene"),
    ],
)
def test_bad_requests_get_typed_errors(raw, cmd, args, kind):
    conn, sim = raw
    with pytest.raises(RemoteEnvError) as info:
        conn.request(cmd, **args)
    assert info.value.kind == kind, str(info.value)
    assert sim.death() is None
    conn.request("reset", seed=1)


def test_step_before_reset_is_a_state_error():
    with Launcher(scene_path("cartpole"), startup_timeout=120.0) as launcher:
        conn = Connection(launcher.sims[0].endpoint, timeout=30.0, death_check=launcher.sims[0].death)
        try:
            with pytest.raises(RemoteEnvError) as info:
                conn.request("step", action=0)
            assert info.value.kind == "state" and "instance 0" in str(info.value)
        finally:
            conn.close()
