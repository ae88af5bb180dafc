"""The parts of remoteenv.integrations.ray that need neither Ray nor a process: placement
options, which scene the nodes are asked for, the scene command line."""

from __future__ import annotations

import json
import os

import pytest

import remoteenv
from remoteenv.agent.launch.sim_command import scene_command
from remoteenv.agent.launch.sim_group import SimGroup, SimHandle
from remoteenv.integrations.ray import RayLauncher
from remoteenv.integrations.ray.placement import STRATEGIES, Placement
from remoteenv.integrations.ray.ray_launcher import scene_on_nodes
from remoteenv.integrations.ray.ray_sim import RaySim
from remoteenv.integrations.ray.sim_actor import resolve_scene
from remoteenv.wire.run_options.options import RunOptions


@pytest.mark.parametrize("strategy", STRATEGIES)
def test_every_ray_strategy_is_accepted(strategy: str) -> None:
    assert Placement(strategy).strategy == strategy


def test_an_unknown_strategy_is_refused_with_the_choices() -> None:
    with pytest.raises(ValueError, match="STRICT_SPREAD"):
        Placement("SCATTER")


def test_a_bundle_holds_cpus_and_extra_resources() -> None:
    assert Placement("PACK", 2, {"GPU": 0.5, "sim_host": 1}).bundle() == {"CPU": 2.0, "GPU": 0.5, "sim_host": 1.0}


def test_zero_cpus_become_a_sliver_because_ray_refuses_empty_bundles() -> None:
    assert 0 < Placement("PACK", 0).bundle()["CPU"] < 0.01


def test_cpus_given_as_a_resource_are_refused() -> None:
    with pytest.raises(ValueError, match="num_cpus_per_process"):
        Placement("PACK", 1, {"CPU": 2})


def test_a_shipped_scene_script_travels_as_its_name() -> None:
    assert scene_on_nodes(remoteenv.scene_path("cartpole")) == "cartpole"
    assert scene_on_nodes(remoteenv.scene_path("reacher")) == "reacher"


def test_another_scene_script_travels_as_its_path(tmp_path: os.PathLike[str]) -> None:
    script = os.path.join(os.fspath(tmp_path), "my_scene.py")
    assert scene_on_nodes(script) == script


def test_a_node_resolves_a_shipped_name_to_its_own_copy() -> None:
    assert resolve_scene("reacher") == remoteenv.scene_path("reacher")


def test_a_node_finds_a_shipped_working_dir_file_by_its_base_name(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "my_scene.py").write_text("")
    assert resolve_scene("/home/someone/else/my_scene.py") == str(tmp_path / "my_scene.py")


def test_a_missing_scene_names_the_fix(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="working_dir"):
        resolve_scene("/nowhere/my_scene.py")


def test_the_scene_command_line_carries_every_launch_option() -> None:
    cmd = scene_command(
        "/s/scene.py",
        "tcp://10.0.0.5:*",
        instance=3,
        worlds=8,
        env_kwargs={"a": 1},
        parent_pid=42,
        ready_file="/d/r.json",
        private_dir="/d",
        seed=24,
        render_mode="rgb_array",
        run=RunOptions(real_time=True, real_time_factor=2.0),
        delay_file="/d/sim-3.delays.json",
        curve_files=("/d/s", "/d/c"),
        allow_remote=True,
        extra_args=["--x"],
        python="py",
    )
    assert cmd[:2] == ["py", "/s/scene.py"]
    opts = dict(zip(cmd[2::1], cmd[3::1]))
    assert opts["--address"] == "tcp://10.0.0.5:*" and opts["--instance"] == "3" and opts["--worlds"] == "8"
    assert json.loads(opts["--env-kwargs"]) == {"a": 1} and opts["--parent-pid"] == "42"
    assert opts["--seed"] == "24" and opts["--render-mode"] == "rgb_array" and opts["--real-time-factor"] == "2.0"
    assert opts["--curve-secret-key-file"] == "/d/s" and opts["--curve-client-keys-file"] == "/d/c"
    assert opts["--delay-file"] == "/d/sim-3.delays.json" and "--action-delay" not in cmd
    assert "--allow-remote" in cmd and "--real-time" in cmd and cmd[-1] == "--x"


def test_without_curve_a_sim_is_never_allowed_beyond_loopback() -> None:
    cmd = scene_command(
        "/s.py",
        "tcp://127.0.0.1:*",
        instance=0,
        worlds=1,
        env_kwargs={},
        parent_pid=1,
        ready_file="r",
        private_dir="d",
        allow_remote=True,
    )
    assert "--allow-remote" not in cmd and "--curve-secret-key-file" not in cmd and "--seed" not in cmd


def test_the_ray_launcher_has_the_sim_group_shape_and_starts_nothing_until_asked() -> None:
    launcher = RayLauncher(strategy="SPREAD", num_cpus_per_process=2)
    assert isinstance(launcher, SimGroup)
    assert launcher.owns_sims and launcher.layout is None and launcher.sims == []
    assert launcher.curve_client_keypair is not None  # CURVE is always on
    launcher.close()
    assert launcher.closed


def test_a_cluster_sim_handle_names_its_node_and_has_no_pipe() -> None:
    sim = RaySim(
        instance=2,
        actor=None,
        endpoint="tcp://10.0.0.7:4000",
        pid=99,
        node_id="ab" * 28,
        node_ip="10.0.0.7",
        host="n7",
        curve_server_key=b"k" * 40,
        generation=1,
    )
    assert isinstance(sim, SimHandle)
    assert sim.pipe is None and sim.node == "10.0.0.7 (Ray node abababababab)"
