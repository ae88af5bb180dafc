"""What the default layout learnt of a scene is remembered per scene file, its
arguments and render mode, for this process only, and at most MAX_SCENES of them."""

from __future__ import annotations

import os

import pytest

from remoteenv.agent.vector import layout_memory
from remoteenv.agent.vector.layout_memory import MAX_SCENES, WorldFacts, recall, remember, scene_key


@pytest.fixture(autouse=True)
def _empty_memory():
    layout_memory.forget_all()
    yield
    layout_memory.forget_all()


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "scene.py"
    path.write_text("# a scene\n")
    return str(path)


FACTS = WorldFacts(cost_s=1e-4, stacked_hooks=True, fit=64)


def test_facts_are_recalled_under_the_same_scene_arguments_and_render_mode(scene):
    remember(scene_key(scene, {"a": 1, "b": [2]}, None), FACTS)
    assert recall(scene_key(scene, {"b": [2], "a": 1}, None)) == FACTS  # argument order does not matter
    assert recall(scene_key(scene, {"a": 2, "b": [2]}, None)) is None
    assert recall(scene_key(scene, {"a": 1, "b": [2]}, "rgb_array")) is None
    assert recall(scene_key(scene + "x", {"a": 1, "b": [2]}, None)) is None


def test_a_changed_scene_file_is_measured_again(scene):
    remember(scene_key(scene, {}, None), FACTS)
    stat = os.stat(scene)
    os.utime(scene, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert recall(scene_key(scene, {}, None)) is None
    remember(scene_key(scene, {}, None), FACTS)
    with open(scene, "a") as f:
        f.write("# grown\n")
    os.utime(scene, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))  # same time, another size
    assert recall(scene_key(scene, {}, None)) is None


def test_nothing_is_remembered_without_a_key(scene, tmp_path):
    assert scene_key(str(tmp_path / "missing.py"), {}, None) is None
    assert scene_key(scene, {"f": object()}, None) is None  # not JSON: no way to tell two calls apart
    remember(None, FACTS)
    assert recall(None) is None


def test_at_most_max_scenes_are_kept_the_oldest_forgotten_first(scene):
    keys = [scene_key(scene, {"i": i}, None) for i in range(MAX_SCENES + 1)]
    for key in keys:
        remember(key, FACTS)
    assert recall(keys[0]) is None
    assert all(recall(key) == FACTS for key in keys[1:])
    remember(keys[1], FACTS)  # remembered again: the newest
    remember(scene_key(scene, {"i": -1}, None), FACTS)
    assert recall(keys[1]) == FACTS and recall(keys[2]) is None
