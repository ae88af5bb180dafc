"""The run options: one object, checked once, and the same on both sides of
the process boundary (the scene command line and the delay file carry it whole)."""

from __future__ import annotations

import dataclasses

import pytest

from remoteenv.agent.launch.sim_command import scene_command, write_sim_delay_file
from remoteenv.agent.launch.sim_group import LaunchSpec
from remoteenv.delays import Categorical, Trace, Uniform
from remoteenv.sim.scene_main import run_options_from_arguments, scene_argument_parser
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import FIXED_STEP

CASES = [
    RunOptions(),
    RunOptions(action_delay=3),
    RunOptions(action_delay=Uniform(0, 3), obs_delay=Categorical([0, 2]), action_delivery="in_order"),
    RunOptions(obs_delay=Trace([0, 1, 2]), obs_delivery="in_order", delayed_rewards=True),
    RunOptions(real_time=True),
    RunOptions(real_time=True, real_time_factor=2.5, real_time_mode=FIXED_STEP),
    RunOptions(real_time=True, link_delay=Uniform(0.001, 0.004, unit="s")),
]


def _through_the_command_line(tmp_path, run: RunOptions) -> tuple[list[str], RunOptions]:
    """The scene command line the launcher builds for ``run``, and the options the sim rebuilds from it."""
    spec = LaunchSpec("/s/scene.py", run=run)
    cmd = scene_command(
        spec.scene,
        "ipc:///x",
        instance=0,
        worlds=1,
        env_kwargs={},
        parent_pid=1,
        ready_file="r",
        private_dir=str(tmp_path),
        run=spec.run,
        delay_file=write_sim_delay_file(str(tmp_path), 0, spec.run.delay_file_text()),
    )
    parser = scene_argument_parser()
    return cmd, run_options_from_arguments(parser, parser.parse_args(cmd[2:]))


@pytest.mark.parametrize("run", CASES, ids=range(len(CASES)))
def test_the_sim_rebuilds_the_options_the_agent_made(tmp_path, run):
    assert _through_the_command_line(tmp_path, run)[1].describe() == run.describe()


def test_the_options_are_one_frozen_object_and_checked_when_made():
    run = RunOptions(real_time=True)
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.real_time = False  # type: ignore[misc]
    with pytest.raises(ValueError, match="real-time regime"):
        RunOptions(real_time_mode=FIXED_STEP)
    with pytest.raises(ValueError, match="real_time_mode must be one of"):
        RunOptions(real_time=True, real_time_mode="elastik")
    with pytest.raises(ValueError, match="obs_delay"):
        RunOptions(obs_delay=-1)
    assert RunOptions(real_time_factor=-1.0).real_time_factor == -1.0  # unused in lock-step, as before: not refused
    assert RunOptions(action_delay=0, obs_delay=Trace([0, 0])).delay_file_text() is None
    assert RunOptions(action_delay=2).timed_steps and RunOptions(real_time=True).timed_steps
    assert not RunOptions().timed_steps and RunOptions().scene_arguments() == []


def test_the_physics_threads_travel_to_the_sim_and_are_checked(tmp_path):
    cmd, rebuilt = _through_the_command_line(tmp_path, RunOptions(physics_threads=2))
    assert cmd[cmd.index("--physics-threads") + 1] == "2"
    assert rebuilt.physics_threads == 2
    assert "--physics-threads" not in RunOptions().scene_arguments()
    for bad in (0, -2, True, 2.0):
        with pytest.raises(ValueError, match="physics_threads"):
            RunOptions(physics_threads=bad)
    with pytest.raises(ValueError, match="physics_threads is lock-step's"):
        RunOptions(real_time=True, physics_threads=2)
