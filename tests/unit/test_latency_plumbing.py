"""The delay plumbing without processes: command-line and launch arguments,
the handshake's description, the lock-step stepper's info and seeding."""

from __future__ import annotations

import argparse
import json

import pytest
from gymnasium import spaces

from remoteenv.agent.launch.sim_command import write_sim_delay_file
from remoteenv.agent.launch.sim_group import LaunchSpec
from remoteenv.delays import Categorical, Constant, Trace, Uniform
from remoteenv.sim.scene_main import seconds_delay_argument, tick_delay_argument
from remoteenv.sim.stepping.lock_step import LockStepper
from remoteenv.wire.codec.spaces import space_to_wire
from remoteenv.wire.delays.delay_file import delays_from_map, read_delay_file
from remoteenv.wire.messages.handshake import parse_handshake
from remoteenv.wire.run_options.options import RunOptions
from tests.unit.test_sim_lock_step import DT, RecordingWorld


def test_delay_specs_round_trip_through_the_delay_file(tmp_path):
    spec = LaunchSpec("x.py", run=RunOptions(action_delay=Uniform(0, 3), obs_delay=2))
    text = spec.run.delay_file_text()
    assert text is not None
    path = write_sim_delay_file(str(tmp_path), 4, text)
    assert path == str(tmp_path / "sim-4.delays.json")
    assert read_delay_file(path) == {"action_delay": Uniform(0, 3), "obs_delay": Constant(2)}
    rt = LaunchSpec("x.py", run=RunOptions(real_time=True, link_delay=Uniform(0.0, 0.01, unit="s")))
    assert delays_from_map(json.loads(rt.run.delay_file_text() or "")) == {"link_delay": Uniform(0.0, 0.01, unit="s")}
    assert json.loads(
        LaunchSpec("x.py", run=RunOptions(real_time=True, link_delay=0.02)).run.delay_file_text() or ""
    ) == {"link_delay": Constant(0.02, unit="s").to_wire()}
    assert LaunchSpec("x.py").run.delay_file_text() is None
    assert (
        LaunchSpec("x.py", run=RunOptions(action_delay=Constant(0), obs_delay=Trace([0, 0]))).run.delay_file_text()
        is None
    )
    assert write_sim_delay_file(str(tmp_path), 5, None) is None and not (tmp_path / "sim-5.delays.json").exists()


def test_a_sim_started_by_hand_still_takes_delays_as_flags():
    assert tick_delay_argument(json.dumps(Uniform(0, 3).to_wire())) == Uniform(0, 3)
    assert tick_delay_argument("2") == Constant(2)
    assert seconds_delay_argument(json.dumps(Uniform(0.0, 0.01, unit="s").to_wire())) == Uniform(0.0, 0.01, unit="s")
    assert seconds_delay_argument("0.02") == Constant(0.02, unit="s")


@pytest.mark.parametrize(
    "text", ["x", "true", "[1]", '{"kind": "uniform", "unit": "s", "low": 0, "high": 1}', "-1", "2.5"]
)
def test_bad_tick_delays_are_refused_on_the_command_line(text):
    with pytest.raises(argparse.ArgumentTypeError):
        tick_delay_argument(text)


def test_a_launch_refuses_delays_of_the_other_mode_before_starting_anything():
    with pytest.raises(ValueError, match="action_delay"):
        LaunchSpec("x.py", run=RunOptions(real_time=True, action_delay=Uniform(0, 2)))
    with pytest.raises(ValueError, match="link_delay"):
        LaunchSpec("x.py", run=RunOptions(link_delay=0.01))
    with pytest.raises(ValueError, match="ticks"):
        LaunchSpec("x.py", run=RunOptions(action_delay=Constant(0.5, unit="s")))
    LaunchSpec("x.py", run=RunOptions(real_time=True, action_delay=Constant(0)))  # zero delays are no delay


def test_the_handshake_describes_random_models_and_makes_steps_timed():
    stepper = LockStepper(RecordingWorld(), RunOptions(action_delay=Categorical([0, 4]), obs_delay=Uniform(0, 2)))  # type: ignore[arg-type]
    stepping = stepper.describe()
    assert stepping["action_delay"] == 4 and stepping["obs_delay"] == 2
    assert stepping["obs_delay_spec"] == Uniform(0, 2).to_wire()
    assert json.loads(json.dumps(stepping)) == stepping  # plain data
    obs_only = LockStepper(RecordingWorld(), RunOptions(obs_delay=1)).describe()  # type: ignore[arg-type]
    discrete = space_to_wire(spaces.Discrete(2))
    reply = {
        "protocol": 1,
        "observation_space": discrete,
        "action_space": discrete,
        "metadata": {"render_modes": [], "dt": DT},
        "stepping": obs_only,
    }
    hs = parse_handshake(reply)
    assert hs.obs_delay == 1 and hs.action_delay == 0 and hs.timed_steps


def test_an_observation_delay_returns_older_observations_with_their_sim_time():
    world = RecordingWorld()
    stepper = LockStepper(world, RunOptions(obs_delay=2))  # type: ignore[arg-type]
    stepper.reset(seed=0, options=None)
    replies = [stepper.step(f"a{t}") for t in range(1, 6)]
    assert world.actions == ["a1", "a2", "a3", "a4", "a5"]  # actions undelayed
    assert [r["obs"][0] for r in replies] == [0, 0, 1, 2, 3]  # x_max(0, t - 2)
    info = replies[3]["info"]
    assert info["obs_delay_ticks"] == 2 and info["obs_sim_time"] == pytest.approx(2 * DT)
    assert info["sim_time"] == pytest.approx(4 * DT) and info["action_delay_ticks"] == 0
    assert info["tick"] == 4 and replies[3]["reward"] == 4.0  # reward and scene info of the tick that ran
    # The agent held x_1 (returned by step 3) when sending a4, due at tick 4, which starts at 3 * DT.
    # ``late`` says whether a tick ran on an older action: a4 acted at once here.
    assert info["latency_ticks"] == 2 and info["late"] is False


def test_the_launch_seed_seeds_delays_until_a_reset_brings_one():
    def latencies(seed_at_launch, reset_seed):
        stepper = LockStepper(RecordingWorld(), RunOptions(action_delay=Uniform(0, 9)), seed=seed_at_launch)  # type: ignore[arg-type]
        stepper.reset(seed=reset_seed, options=None)
        return [stepper.step(t)["info"]["latency_ticks"] for t in range(12)]

    assert latencies(5, None) == latencies(5, None) == latencies(None, 5)
    assert latencies(5, None) != latencies(6, None)
