"""The wheel ships what users need besides the modules: py.typed, the scene templates, the models."""

from __future__ import annotations

import os
import sys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_package_data_lists_py_typed_templates_and_models() -> None:
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        data = tomllib.load(f)["tool"]["setuptools"]["package-data"]
    assert "py.typed" in data["remoteenv"]
    assert os.path.isfile(os.path.join(ROOT, "remoteenv", "py.typed"))
    assert "scene_template/*.tmpl" in data["remoteenv.cli"]
    templates = os.listdir(os.path.join(ROOT, "remoteenv", "cli", "scene_template"))
    assert {"pyproject.toml.tmpl", "scene.py.tmpl", "model.xml.tmpl", "init.py.tmpl", "test.py.tmpl"} <= set(templates)
    for scene in ("cartpole", "reacher", "hexapod"):
        assert data[f"remoteenv.scenes.{scene}"] == ["*.xml"]


def test_every_package_of_the_tree_is_listed() -> None:
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        listed = set(tomllib.load(f)["tool"]["setuptools"]["packages"])
    found = {
        os.path.relpath(folder, ROOT).replace(os.sep, ".")
        for folder, _, files in os.walk(os.path.join(ROOT, "remoteenv"))
        if "__init__.py" in files and "__pycache__" not in folder
    }
    assert found <= listed, f"packages missing from pyproject.toml: {sorted(found - listed)}"


def test_cartpole_registration_carries_cartpole_v1_threshold() -> None:
    import gymnasium as gym

    import remoteenv  # noqa: F401

    assert gym.spec("remoteenv/CartPole-v0").reward_threshold == gym.spec("CartPole-v1").reward_threshold == 475.0


def test_torchrl_and_ray_are_compatible_ranges_not_exact_pins():
    """Issue 28, item 6: exact pins blocked every later release of either."""
    from packaging.requirements import Requirement

    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        extras = tomllib.load(f)["project"]["optional-dependencies"]
    for extra, name in (("torchrl", "torchrl"), ("ray", "ray")):
        (requirement,) = [Requirement(r) for r in extras[extra] if Requirement(r).name == name]
        operators = sorted(spec.operator for spec in requirement.specifier)
        assert operators == ["<", ">="], f"{extra}: {requirement} is not a lower bound and an upper one"
