"""The exact twin's recording file and its step-by-step comparison, without processes."""

from __future__ import annotations

import json
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.delays import Uniform
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
from remoteenv.latency.twin.replay import exact_twin_kwargs


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
    assert doc["format"] == "remoteenv.real_time_recording" and doc["version"] == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"version": 3}, "version 3"),
        ({"format": "trace"}, "not a remoteenv real-time recording"),
        ({"real_time_mode": "rubber"}, "real_time_mode"),
        ({"action_substeps": [4]}, "action_substeps"),
        ({"action_substeps": [4, -1]}, "ints >= 0"),
        ({"rewards": [1.0]}, "one value per step"),
        ({"obs_digests": ["a"]}, "obs_digests"),
        ({"seed": "7"}, "seed"),
        ({"latency_ticks": [0.4, "x"]}, "latency_ticks"),
        # Issue 35, item 6: raw OverflowError and a seed Gymnasium refuses at reset.
        ({"rewards": [1.0, 10**400]}, "rewards must be numbers a float holds"),
        ({"latency_ticks": [10**400, None]}, "latency_ticks must be finite numbers"),
        ({"seed": -1}, "seed must be an int in 0..2"),
        ({"seed": 2**64}, "seed must be an int in 0..2"),
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


class HandshakeStandIn(dict):
    real_time = True
    real_time_mode = "elastic"


class LinkedStandIn(RealTimeStandIn):
    """A real-time stand-in made as gym.make makes an env (its arguments kept), with a link and a time limit."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__()
        self._init_args = ((), kwargs)
        self.handshake = HandshakeStandIn(
            stepping={
                "mode": "real_time",
                "real_time_factor": 2.0,
                "link_delay_spec": Uniform(0, 0.01, unit="s").to_wire(),
            }
        )

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, {**info, "link_delay_s": 0.001 * self.n}


def recorded_with_env() -> RecordedEpisode:
    stand_in = LinkedStandIn(
        continuous=True,
        level=3,
        real_time=True,
        real_time_factor=2.0,
        link_delay=Uniform(0, 0.01, unit="s"),
        timeout=5.0,
        launcher=object(),
        shaper=lambda x: x,
    )
    rec = LatencyRecorder(gym.wrappers.TimeLimit(stand_in, 3))
    rec.reset(seed=4)
    for _ in range(3):
        rec.step(np.zeros(1, np.float32))
    return rec.episodes[-1]


def test_a_recording_keeps_its_env_and_link_delays_and_reads_back():
    ep = recorded_with_env()
    assert ep.link_delays == [0.001, 0.002, 0.003]
    env = ep.env
    assert env is not None
    # The world's arguments are kept; where and how the sim ran is not; what JSON cannot hold is named.
    assert env.kwargs == {"continuous": True, "level": 3} and env.unrecorded == ["shaper"]
    assert env.max_episode_steps == 3 and env.real_time_factor == 2.0
    assert env.link_delay == Uniform(0, 0.01, unit="s").to_wire()
    doc = json.loads(json.dumps(recording_document(ep, "remoteenv/CartPole-v0")))
    loaded, _ = episode_from_document(doc)
    assert loaded == ep
    # A version-1 recording (no env, no link delays) still reads.
    old = {k: v for k, v in recording_document(episode(), "x").items() if k not in ("env", "link_delays")}
    assert episode_from_document({**old, "version": 1})[0] == episode()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"link_delays": [0.1]}, "link_delays"),
        ({"link_delays": [0.1, 0.2, -1.0]}, "link_delays"),
        ({"env": []}, "'env' must be a map"),
        ({"env": {"kwargs": {"a": 1}, "max_episode_steps": 3, "real_time_factor": 0.0}}, "real_time_factor"),
        ({"env": {"kwargs": {"a": {"remoteenv_delay_spec": {"kind": "?"}}}, "real_time_factor": 1.0}}, "delay kind"),
    ],
)
def test_a_malformed_env_or_link_record_is_refused_naming_the_field(change, message):
    doc = {**recording_document(recorded_with_env(), "x"), **change}
    with pytest.raises(ValueError, match=message):
        episode_from_document(doc, "recording ep.json")


def test_the_twin_is_built_from_the_recording_and_refuses_contradictions_in_one_line():
    ep = recorded_with_env()
    what = "recording ep.json"
    kwargs = exact_twin_kwargs(ep, None, {"timeout": 9.0, "shaper": str}, what)
    assert kwargs == {
        "real_time": True,
        "real_time_mode": "elastic",
        "continuous": True,
        "level": 3,
        "real_time_factor": 2.0,
        "link_delay": Uniform(0, 0.01, unit="s"),
        "timeout": 9.0,
        "shaper": str,
        "max_episode_steps": 3,
    }
    # The recorded values may be repeated (a number for a constant spec too); anything else is refused.
    assert exact_twin_kwargs(ep, 3, {"continuous": True, "shaper": str, "link_delay": Uniform(0, 0.01, unit="s")}, what)
    for explicit, limit, message in [
        ({"continuous": False, "shaper": str}, None, "continuous=False contradicts recording ep.json"),
        ({"shaper": str, "render_mode": "rgb_array"}, None, "render_mode='rgb_array' is not in recording ep.json"),
        ({"shaper": str, "link_delay": 0.004}, None, "link_delay=0.004 contradicts"),
        ({"shaper": str, "real_time_mode": "fixed_step"}, None, "real_time_mode='fixed_step' contradicts"),
        ({"shaper": str}, 10, "max_episode_steps=10 contradicts recording ep.json \\(3\\)"),
        ({}, None, "could not keep shaper: pass them"),
    ]:
        with pytest.raises(ValueError, match=message) as err:
            exact_twin_kwargs(ep, limit, explicit, what)
        assert "\n" not in str(err.value)


def test_saving_into_a_missing_folder_names_the_users_path(tmp_path):
    target = tmp_path / "missing" / "ep.json"
    with pytest.raises(FileNotFoundError) as err:
        save_recording(episode(), target, "x")
    assert str(target) in str(err.value) and "does not exist" in str(err.value) and ".tmp" not in str(err.value)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        make_twin("remoteenv/CartPole-v0", tmp_path / "nothing.json")


# Replays are bounded before any sim starts; a FIFO given as a recording is named as one.


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"resets_after_seed": 10**12}, "unseeded resets after its seed, more than the 10000"),
        ({"ticks_elapsed": [1, 1_001], "rewards": [0.0, 0.0]}, "lasted 1001 ticks, more than the 1000"),
    ],
)
def test_a_replay_beyond_its_bounds_is_refused_before_a_sim_starts(tmp_path, change, message):
    doc = {**recording_document(episode(), "remoteenv/CartPole-v0"), **change}
    path = tmp_path / "ep.json"
    path.write_text(json.dumps(doc))
    loaded, _ = load_recording(path)  # a figure the lock-step twin may still use
    with pytest.raises(ValueError, match=message):
        make_twin("remoteenv/CartPole-v0", path)  # a sim would fail the test's no-process fixture


def test_a_fifo_given_as_a_recording_is_refused_as_no_regular_file(tmp_path):
    import os

    from remoteenv.wire.files.file_reads import UnreadableFile

    fifo = tmp_path / "ep.json"
    os.mkfifo(fifo)
    with pytest.raises(UnreadableFile, match="recording or trace file .* is not a regular file"):
        make_twin("remoteenv/CartPole-v0", fifo)
