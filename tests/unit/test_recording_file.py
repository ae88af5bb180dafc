"""The exact twin's recording file and its step-by-step comparison, without processes."""

from __future__ import annotations

import json
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.latency.twin import (
    LatencyRecorder,
    RecordedEpisode,
    first_difference,
    load_recording,
    make_twin,
    save_recording,
)
from remoteenv.latency.twin.digest import obs_digest
from remoteenv.latency.twin.recording_file import episode_from_document, recording_document


def episode() -> RecordedEpisode:
    return RecordedEpisode(
        7,
        1,
        ticks_elapsed=[1, 3],
        latency_ticks=[0.4, None],
        rewards=[1.0, 3.0],
        terminated=True,
        mode="fixed_step",
        action_substeps=[4, 40],
        obs_digests=["a", "b", "c"],
    )


def test_a_recording_round_trips_through_its_file(tmp_path):
    path = save_recording(episode(), tmp_path / "ep.json", "remoteenv/CartPole-v0")
    loaded, env_id = load_recording(path)
    assert loaded == episode() and env_id == "remoteenv/CartPole-v0"
    doc = json.loads(open(path).read())
    assert doc["format"] == "remoteenv.real_time_recording" and doc["version"] == 1


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"version": 2}, "version 2"),
        ({"format": "trace"}, "not a remoteenv real-time recording"),
        ({"real_time_mode": "rubber"}, "real_time_mode"),
        ({"action_substeps": [4]}, "action_substeps"),
        ({"action_substeps": [4, -1]}, "ints >= 0"),
        ({"rewards": [1.0]}, "one value per step"),
        ({"obs_digests": ["a"]}, "obs_digests"),
        ({"seed": "7"}, "seed"),
        ({"latency_ticks": [0.4, "x"]}, "latency_ticks"),
    ],
)
def test_a_malformed_recording_is_refused_naming_the_field(change, message):
    doc = {**recording_document(episode(), "x"), **change}
    with pytest.raises(ValueError, match=message):
        episode_from_document(doc)


def replay_of(ep: RecordedEpisode, **change) -> dict:
    return {
        "obs_digests": list(ep.obs_digests),
        "rewards": list(ep.rewards),
        "terminated": ep.terminated,
        "truncated": ep.truncated,
        **change,
    }


def test_the_first_difference_names_the_step_and_what_differs():
    ep = episode()
    assert first_difference(ep, replay_of(ep)) is None
    assert first_difference(ep, replay_of(ep, obs_digests=["x", "b", "c"])) == {"step": 0, "differs": ["obs"]}
    assert first_difference(ep, replay_of(ep, rewards=[1.0, 2.0])) == {"step": 2, "differs": ["reward"]}
    assert first_difference(ep, replay_of(ep, terminated=False, truncated=True)) == {
        "step": 2,
        "differs": ["terminated", "truncated"],
    }
    longer = replay_of(ep, obs_digests=["a", "b", "c", "d"], rewards=[1.0, 3.0, 1.0])
    assert first_difference(ep, longer) == {"step": 3, "differs": ["steps"]}


def test_a_fingerprint_changes_with_any_bit_dtype_or_shape():
    a = np.array([0.1, 0.2], np.float32)
    b = a.copy()
    b.view(np.uint32)[1] ^= 1  # the last bit of the second value
    assert obs_digest(a) == obs_digest(a.copy()) and obs_digest(a) != obs_digest(b)
    assert obs_digest(a) != obs_digest(a.astype(np.float64)) and obs_digest(a) != obs_digest(a.reshape(2, 1))
    assert obs_digest({"x": a, "y": 1}) != obs_digest({"x": a, "y": 2})


class RealTimeStandIn(gym.Env):
    """Replies as a real-time sim does, with substeps; step ``restart_at`` is lost to a restart, ``raise_at`` raises."""

    observation_space = spaces.Box(-1, 1, (1,))
    action_space = spaces.Box(-1, 1, (1,))

    def __init__(self, restart_at: int = 0, raise_at: int = 0) -> None:
        self.restart_at, self.raise_at, self.n = restart_at, raise_at, 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        self.n = 0
        return np.zeros(1, np.float32), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self.n += 1
        if self.n == self.raise_at:
            raise TimeoutError("no reply")
        if self.n == self.restart_at:
            return np.zeros(1, np.float32), 0.0, False, True, {"remoteenv_restarted": True}
        info = {"ticks_elapsed": 1, "latency_ticks": 0.5, "action_sim_time": 1.0, "action_substep": 10 * self.n - 5}
        return np.full(1, self.n, np.float32), 1.0, False, False, {**info, "substep": 10 * self.n}


def test_what_cannot_be_replayed_is_named_and_the_twin_refuses_it():
    rec = LatencyRecorder(RealTimeStandIn(restart_at=3))
    rec.reset(seed=1)
    for _ in range(3):
        *_, truncated, _ = rec.step(np.zeros(1, np.float32))
    assert truncated and rec.episodes[-1].action_substeps == [5, 15]
    assert "restarted at step 3" in str(rec.episodes[-1].unreplayable)

    rec = LatencyRecorder(RealTimeStandIn(raise_at=2))
    rec.reset(seed=1)
    rec.step(np.zeros(1, np.float32))
    with pytest.raises(TimeoutError):
        rec.step(np.zeros(1, np.float32))
    assert "step 2 raised TimeoutError" in str(rec.episodes[-1].unreplayable)

    rec.reset(seed=1, options={"level": 2})
    rec.step(np.zeros(1, np.float32))
    rec.reset(seed=1)
    assert "options" in str(rec.episodes[-1].unreplayable)
    assert rec.current is not None and rec.current.unreplayable is None  # a plain seeded reset starts clean
    for bad in rec.episodes:
        with pytest.raises(ValueError, match="cannot be replayed exactly"):
            make_twin("remoteenv/CartPole-v0", bad)
