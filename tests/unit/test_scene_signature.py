"""Scene keyword arguments are checked against the scene script's source before launching."""

from __future__ import annotations

import pytest

import remoteenv
from remoteenv.agent.errors import LaunchError, SceneArgumentError
from remoteenv.agent.session.scene_signature import check_scene_kwargs


def test_shipped_scene_refuses_an_unknown_keyword_as_python_would() -> None:
    path = remoteenv.scene_path("cartpole")
    check_scene_kwargs(path, ["continuous", "render_mode", "width"])
    with pytest.raises(SceneArgumentError) as err:
        check_scene_kwargs(path, ["frameskip"])
    # TorchRL retries without frameskip when it sees exactly this wording.
    assert "CartPoleEnv.__init__() got an unexpected keyword argument 'frameskip'" in str(err.value)
    assert isinstance(err.value, TypeError) and isinstance(err.value, LaunchError)


@pytest.mark.parametrize(
    "source",
    [
        "from elsewhere import Env\nrun_scene(Env)\n",  # factory not in the script
        "class Env(Base):\n    pass\nrun_scene(Env)\n",  # no __init__ of its own
        "class Env:\n    def __init__(self, **kw): pass\nrun_scene(Env)\n",  # takes anything
        "this is not python",
    ],
)
def test_unknown_signatures_refuse_nothing(tmp_path, source: str) -> None:
    script = tmp_path / "scene.py"
    script.write_text(source)
    check_scene_kwargs(script, ["anything"])


def test_a_factory_function_and_keyword_only_parameters(tmp_path) -> None:
    script = tmp_path / "scene.py"
    script.write_text(
        "def make(render_mode=None, *, size=1):\n    pass\n\nif __name__ == '__main__':\n    run_scene(make)\n"
    )
    check_scene_kwargs(script, ["size", "render_mode"])
    with pytest.raises(SceneArgumentError, match=r"make\(\) got an unexpected keyword argument 'width'"):
        check_scene_kwargs(script, ["width"])


def test_a_missing_script_is_left_to_the_launcher(tmp_path) -> None:
    check_scene_kwargs(tmp_path / "nope.py", ["x"])


@pytest.mark.parametrize(
    ("source", "says"),
    [
        ("class Env(Base):\n    stacked_hooks = True\nrun_scene(Env)\n", True),
        ("class Env(Base):\n    stacked_hooks: bool = True\n", True),
        ("class Env(Base):\n    stacked_hooks = False\n", False),
        ("class Env(Base):\n    pass\n", False),  # inherited from elsewhere: not seen
        ("stacked_hooks = True\n", False),  # not a class attribute
        ("class Env(Base):\n    def f(self):\n        stacked_hooks = True\n", False),  # a local, not the class's
        ("this is not python", False),
    ],
)
def test_a_script_says_it_steps_its_worlds_as_one_batch_only_in_a_class_body(tmp_path, source, says) -> None:
    from remoteenv.agent.session.scene_signature import declares_stacked_hooks

    path = tmp_path / "scene.py"
    path.write_text(source)
    assert declares_stacked_hooks(path) is says


def test_the_shipped_scenes_say_they_step_as_one_batch(tmp_path) -> None:
    from remoteenv.agent.session.scene_signature import declares_stacked_hooks

    assert all(declares_stacked_hooks(remoteenv.scene_path(name)) for name in ("cartpole", "reacher", "hexapod"))
    assert not declares_stacked_hooks(tmp_path / "missing.py")
