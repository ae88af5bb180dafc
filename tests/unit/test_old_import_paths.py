"""Every import path users had before the tree was regrouped still works, and
gives the very objects of the new place (thin re-exports, nothing copied)."""

from __future__ import annotations

import importlib
import runpy
import sys

import pytest

#: old public module -> the module that now defines its names
FACES = {
    "remoteenv.wrappers": "remoteenv.latency.action_history",
    "remoteenv.latency_twin": "remoteenv.latency.twin",
    "remoteenv.latency_study": "remoteenv.latency.study",
    "remoteenv.rllib": "remoteenv.integrations.rllib",
    "remoteenv.ray": "remoteenv.integrations.ray",
    "remoteenv.camera_video": "remoteenv.integrations.camera_video",
}
#: faces of optional libraries: checked where the library is installed
OPTIONAL_FACES = {
    "remoteenv.sb3": ("stable_baselines3", "remoteenv.integrations.sb3"),
    "remoteenv.torchrl": ("torchrl", "remoteenv.integrations.torchrl"),
    "remoteenv.torch": ("torch", "remoteenv.integrations.frame_dataset"),
}
STUDY_MODULES = {
    "design": "design",
    "markov_check": "markov_check",
    "references": "references",
    "results": "results",
    "resumed": "resumed",
    "runner": "runner",
    "spaces": "trainable_spaces",
    "training": "training",
    "twin_check": "twin_check",
}


def _same_names(old: str, new: str) -> None:
    face, real = importlib.import_module(old), importlib.import_module(new)
    assert face.__all__, old
    for name in face.__all__:
        assert getattr(face, name) is getattr(real, name), f"{old}.{name}"


@pytest.mark.parametrize("old", sorted(FACES))
def test_an_old_module_path_gives_the_new_modules_objects(old):
    _same_names(old, FACES[old])


@pytest.mark.parametrize("old", sorted(OPTIONAL_FACES))
def test_an_old_adapter_path_gives_the_new_modules_objects(old):
    library, new = OPTIONAL_FACES[old]
    pytest.importorskip(library)
    _same_names(old, new)


@pytest.mark.parametrize("old", sorted(STUDY_MODULES))
def test_the_studys_old_submodule_paths_are_the_new_modules(old):
    module = importlib.import_module(f"remoteenv.latency_study.{old}")
    assert module is importlib.import_module(f"remoteenv.latency.study.{STUDY_MODULES[old]}")
    assert getattr(importlib.import_module("remoteenv.latency_study"), old) is module


def test_the_controllers_and_delays_and_protocol_faces_still_name_everything():
    from remoteenv import controllers, delays, protocol
    from remoteenv.latency import predictors
    from remoteenv.scene_controllers import cartpole, hexapod, reacher
    from remoteenv.wire import protocol as wire_protocol
    from remoteenv.wire.delays import delay_specs

    assert controllers.CartpolePredictor is predictors.CartpolePredictor
    assert controllers.cartpole_continuous is cartpole.cartpole_continuous
    assert controllers.hexapod_tripod is hexapod.hexapod_tripod and controllers.reacher_reach is reacher.reacher_reach
    assert delays.Uniform is delay_specs.Uniform and protocol.pack is wire_protocol.pack
    for face in (controllers, delays, protocol):
        assert all(hasattr(face, name) for name in face.__all__)


def test_the_old_markov_check_command_still_runs(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["markov_check", "--help"])
    monkeypatch.delitem(sys.modules, "remoteenv.latency_study.markov_check", raising=False)  # as in a fresh process
    with pytest.raises(SystemExit) as end:
        runpy.run_module("remoteenv.latency_study.markov_check", run_name="__main__")
    assert end.value.code == 0 and "--models" in capsys.readouterr().out
