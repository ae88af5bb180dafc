"""What the SimGroup implementations check before any process starts."""

from __future__ import annotations

import os

import pytest

from remoteenv.agent.launch.attach import AttachedSim, AttachedSims, LaunchInfo
from remoteenv.agent.launch.launcher import Launcher
from remoteenv.agent.launch.processes import pid_alive
from remoteenv.agent.launch.sim_group import LaunchSpec, SimLayout
from remoteenv.agent.session.sim_session import choose_group


def test_launch_spec_checks_its_fields():
    spec = LaunchSpec("scene.py", 2, 3, seed=10, env_kwargs={"a": 1})
    assert spec.instance_seed(0) == 10 and spec.instance_seed(1) == 13
    assert LaunchSpec("scene.py").instance_seed(5) is None
    with pytest.raises(ValueError, match=">= 1"):
        LaunchSpec("scene.py", 0)
    with pytest.raises(TypeError, match="JSON-serializable"):
        LaunchSpec("scene.py", env_kwargs={"f": object()})


def test_a_launcher_without_a_scene_takes_no_launch_arguments():
    with pytest.raises(TypeError, match="num_instances, seed"):
        Launcher(num_instances=2, seed=1)
    with pytest.raises(ValueError, match="transport"):
        Launcher(transport="carrier pigeon")
    with pytest.raises(ValueError, match="requires CURVE"):
        Launcher(bind_host="0.0.0.0", curve=False)


def test_an_unstarted_launcher():
    launcher = Launcher(transport="tcp", curve=True)
    assert launcher.curve_client_keypair is not None
    assert launcher.layout is None and launcher.sims == [] and launcher.pids == []
    with pytest.raises(RuntimeError, match="start"):
        _ = launcher.workdir
    launcher.close()
    with pytest.raises(RuntimeError, match="already"):
        launcher.start(LaunchSpec("scene.py"))


def test_a_missing_scene_is_named():
    with pytest.raises(FileNotFoundError, match="nowhere.py"):
        Launcher("/nowhere.py")
    with pytest.raises(FileNotFoundError, match="nowhere.py"):
        Launcher().start(LaunchSpec("/nowhere.py"))


def test_attached_sims_have_a_fixed_layout_and_cannot_restart(tmp_path):
    info = LaunchInfo(
        scene="s.py",
        worlds_per_instance=2,
        real_time=False,
        path=str(tmp_path / "l.json"),
        launcher_pid=5,
        instances=[AttachedSim(0, "ipc:///a", None), AttachedSim(3, "ipc:///b", None)],
    )
    sims = AttachedSims(info)
    assert sims.layout == SimLayout(2, 2, False, f"launch-info file {tmp_path / 'l.json'}")
    assert not sims.owns_sims and sims.sims[1].node is None and sims.sims[1].pipe is None
    with pytest.raises(Exception, match="cannot restart sim instance 3"):
        sims.restart(1)
    with pytest.raises(RuntimeError, match="running already"):
        sims.start(LaunchSpec("s.py"))
    assert choose_group(None, sims) is sims
    with pytest.raises(Exception, match=r"no instance\(s\) \[7\]"):
        AttachedSims(info, [7])


def test_a_sim_on_another_host_is_not_watched():
    remote = AttachedSim(0, "tcp://elsewhere:5555", pid=os.getpid() + 10**7, local=False, host="elsewhere")
    assert remote.node == "elsewhere" and remote.death() is None


def test_pid_alive():
    assert pid_alive(os.getpid())
    assert not pid_alive(2**22 + 12345)  # above Linux's pid_max
