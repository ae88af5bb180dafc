"""A scene's model file: compiled once per text, a model of its own per world."""

from __future__ import annotations

import types
from pathlib import Path

import mujoco
import numpy as np
import pytest

from remoteenv.sim.scene import model_file
from remoteenv.sim.scene.model_file import CACHE_SIZE, forget_models, load_model

ARM = """<mujoco model="arm{tag}">
  <option timestep="0.01" integrator="RK4"/>
  <worldbody>
    <body name="link" pos="0 0 0.1">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02" mass="{mass}"/>
    </body>
  </worldbody>
  <actuator><motor joint="hinge" gear="2"/></actuator>
</mujoco>
"""


@pytest.fixture(autouse=True)
def _fresh_cache():
    forget_models()
    yield
    forget_models()


@pytest.fixture
def compiles(monkeypatch):
    """How many times the module compiled a file (MuJoCo's compile, counted)."""
    paths: list[str] = []

    def from_xml_path(path: str) -> mujoco.MjModel:
        paths.append(path)
        return mujoco.MjModel.from_xml_path(path)

    monkeypatch.setattr(
        model_file, "mujoco", types.SimpleNamespace(MjModel=types.SimpleNamespace(from_xml_path=from_xml_path))
    )
    return paths


def write(path: Path, text: str) -> str:
    path.write_text(text)
    return str(path)


def test_one_text_is_compiled_once_and_every_world_gets_a_model_of_its_own(tmp_path, compiles):
    first = write(tmp_path / "a.xml", ARM.format(tag="", mass=1.0))
    second = write(tmp_path / "b.xml", ARM.format(tag="", mass=1.0))  # the same text elsewhere
    models = [load_model(first, "Arm"), load_model(first, "Arm"), load_model(second, "Arm")]
    assert compiles == [first]
    assert len({id(m) for m in models}) == 3
    models[1].body_mass[1] = 7.0  # a scene randomising one world's model
    assert models[0].body_mass[1] == pytest.approx(1.0)
    assert load_model(first, "Arm").body_mass[1] == pytest.approx(1.0)


def test_a_copy_steps_bit_for_bit_as_a_fresh_compile(tmp_path):
    path = write(tmp_path / "arm.xml", ARM.format(tag="", mass=1.0))
    load_model(path, "Arm")
    copied = load_model(path, "Arm")
    fresh = mujoco.MjModel.from_xml_path(path)
    trajectories = []
    for model in (copied, fresh):
        data = mujoco.MjData(model)
        rows = []
        for k in range(60):
            data.ctrl[:] = np.sin(0.1 * k)
            mujoco.mj_step(model, data)
            rows.append(np.concatenate([data.qpos, data.qvel]))
        trajectories.append(np.array(rows))
    np.testing.assert_array_equal(trajectories[0], trajectories[1])


def test_a_rewritten_file_is_compiled_again(tmp_path, compiles):
    path = tmp_path / "arm.xml"
    heavy = load_model(write(path, ARM.format(tag="", mass=1.0)), "Arm")
    light = load_model(write(path, ARM.format(tag="", mass=0.25)), "Arm")
    assert len(compiles) == 2
    assert heavy.body_mass[1] == pytest.approx(1.0)
    assert light.body_mass[1] == pytest.approx(0.25)


def test_a_text_that_refers_to_another_file_is_compiled_every_time(tmp_path, compiles):
    write(tmp_path / "part.xml", '<mujoco><worldbody><geom type="sphere" size="0.1"/></worldbody></mujoco>')
    path = write(tmp_path / "scene.xml", '<mujoco><include file="part.xml"/></mujoco>')
    first = load_model(path, "Scene")
    write(tmp_path / "part.xml", '<mujoco><worldbody><geom type="sphere" size="0.3"/></worldbody></mujoco>')
    second = load_model(path, "Scene")
    assert len(compiles) == 2
    assert first.geom_size[0, 0] == pytest.approx(0.1)
    assert second.geom_size[0, 0] == pytest.approx(0.3)


def test_the_kept_compiles_are_bounded(tmp_path, compiles):
    paths = [write(tmp_path / f"arm{i}.xml", ARM.format(tag=i, mass=1.0)) for i in range(CACHE_SIZE + 2)]
    for path in paths:
        load_model(path, "Arm")
    assert len(model_file._compiled) == CACHE_SIZE
    load_model(paths[0], "Arm")  # the oldest was let go: compiled again
    assert compiles.count(paths[0]) == 2
    load_model(paths[-1], "Arm")  # the newest is kept
    assert compiles.count(paths[-1]) == 1


def test_a_missing_file_names_the_scene(tmp_path):
    with pytest.raises(FileNotFoundError, match="Arm: MJCF model file"):
        load_model(str(tmp_path / "nowhere.xml"), "Arm")


def test_a_file_that_does_not_compile_is_refused_every_time(tmp_path, compiles):
    path = write(tmp_path / "bad.xml", "<mujoco><worldbody><geom type='sphere'/></worldbody>")
    for _ in range(2):
        with pytest.raises(ValueError):
            load_model(path, "Bad")
    assert len(compiles) == 2
