"""``python -m remoteenv new-scene`` writes a package that installs with pip and passes its own tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from remoteenv.cli import main as cli_main
from remoteenv.cli.new_scene import write_package

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _assert_generated_tests_pass(tests: str, cwd: Path, env: dict[str, str]) -> None:
    """The generated package's own four tests pass, run with pytest on ``tests`` from ``cwd``."""
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", tests],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "4 passed" in done.stdout


def test_generated_package_installs_and_passes_check_env(tmp_path, capsys):
    pkg, target = tmp_path / "pkg", tmp_path / "site"
    assert cli_main(["new-scene", "point_mass", "--dir", str(pkg)]) == 0
    assert "pip install -e" in capsys.readouterr().out
    # Into a private target dir: nothing is left behind in the test venv.
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(target),
            str(pkg),
        ],
        check=True,
        timeout=300,
    )
    assert (target / "point_mass" / "point_mass.xml").is_file()  # the model ships as package data
    assert (pkg / "src" / "point_mass" / "point_mass_scene.py").is_file()  # a src layout
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(target), ROOT]))
    where = subprocess.run(
        [sys.executable, "-c", "import point_mass; print(point_mass.__file__)"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert where.stdout.strip().startswith(str(target))  # the installed copy, not the source
    _assert_generated_tests_pass(str(pkg / "tests"), tmp_path, env)


def _private_venv(where):
    """A venv without pip that sees the test venv's packages and this checkout's
    remoteenv (a .pth file each), so an editable install lands in it alone."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(where)], check=True, timeout=120)
    python = where / "bin" / "python"
    site = subprocess.run(
        [str(python), "-c", "import site; print(site.getsitepackages()[0])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    main_site = next(p for p in sys.path if p.endswith("site-packages") and os.path.isdir(p))
    with open(os.path.join(site, "remoteenv_test.pth"), "w") as f:
        f.write(f"{ROOT}\n{main_site}\n")
    return python


def test_editable_package_works_in_the_folder_it_was_made_in(tmp_path):
    # As the scaffold's "next:" lines say: new-scene NAME, pip install -e NAME,
    # then the demo of its id, run where new-scene was run. There a folder
    # named like the package (the project folder) is on the import path; with
    # the package directly in it, Python imported that folder as an empty
    # namespace package and the id was not found.
    python = _private_venv(tmp_path / "venv")
    env = dict(os.environ, PYTHONPATH="", MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    made = subprocess.run(
        [str(python), "-m", "remoteenv", "new-scene", "ball_plate"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert made.returncode == 0, made.stderr
    assert f'pip install -e "{tmp_path / "ball_plate"}[test]"' in made.stdout
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps"]
        + ["--no-build-isolation", "-e", str(tmp_path / "ball_plate")],
        check=True,
        timeout=300,
    )
    demo = subprocess.run(
        [str(python), "-m", "remoteenv", "demo", "ball_plate:ball_plate/BallPlate-v0", "--episodes", "1"]
        + ["--max-steps", "5"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert demo.returncode == 0, demo.stdout + demo.stderr
    assert "steps    5" in demo.stdout


def test_the_demo_names_a_folder_that_hides_a_package(tmp_path):
    (tmp_path / "ghost_pkg").mkdir()  # a project folder without a src layout looks like this
    out = subprocess.run(
        [sys.executable, "-m", "remoteenv", "demo", "ghost_pkg:ghost_pkg/GhostPkg-v0"],
        cwd=tmp_path,
        env=dict(os.environ, PYTHONPATH=ROOT),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode != 0
    assert "empty namespace package" in out.stderr and str(tmp_path / "ghost_pkg") in out.stderr
    assert "use 'package:namespace/Name-v0'" not in out.stderr  # the form the user just used


def test_the_readme_installs_remoteenv_first(tmp_path):
    write_package("ball_plate", tmp_path / "p")
    readme = (tmp_path / "p" / "README.md").read_text()
    assert "installs the package (and remoteenv)" not in readme
    assert readme.index("pip install /path/to/remoteenv") < readme.index('pip install -e ".[test]"')


def test_the_package_recipe_installs_pytest_and_runs_that_one(tmp_path):
    """Issue 28, item 6: the recipe ran the system's pytest, which could not import gymnasium."""
    write_package("ball_plate", tmp_path / "p")
    readme = (tmp_path / "p" / "README.md").read_text()
    guide = (Path(__file__).resolve().parents[2] / "docs" / "env-package.md").read_text()
    assert 'pip install -e ".[test]"' in readme and 'pip install -e "my_arm[test]"' in guide
    for text in (readme, guide):
        commands = [line.split("#")[0].strip() for line in text.splitlines()]
        assert any("python -m pytest" in c for c in commands)
        assert not any(c == "pytest" or c.startswith("pytest ") or "&& pytest" in c for c in commands)
    pyproject = (tmp_path / "p" / "pyproject.toml").read_text()
    assert 'test = ["pytest' in pyproject  # the extra the recipe names


@pytest.mark.parametrize("name", ["remoteenv", "numpy", "os", "json", "gymnasium"])
def test_names_of_importable_modules_are_refused(tmp_path, name, capsys):
    with pytest.raises(ValueError, match=f"importable module '{name}' exists"):
        write_package(name, tmp_path / "x")
    assert not (tmp_path / "x").exists()
    assert cli_main(["new-scene", name, "--dir", str(tmp_path / "y")]) == 2
    assert "pick another name" in capsys.readouterr().err


def test_help_shows_how_the_id_is_formed(capsys):
    with pytest.raises(SystemExit):
        cli_main(["new-scene", "--help"])
    text = capsys.readouterr().out
    assert "Camel-v0" not in text
    assert "ball_plate/BallPlate-v0" in text


def test_names_and_directories_are_checked(tmp_path):
    with pytest.raises(ValueError, match="not usable"):
        write_package("Bad-Name", tmp_path / "x")
    with pytest.raises(ValueError, match="not usable"):
        write_package("class", tmp_path / "x")
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "file").write_text("mine")
    with pytest.raises(FileExistsError, match="not an empty directory"):
        write_package("ok", tmp_path / "busy")
    assert (tmp_path / "busy" / "file").read_text() == "mine"
    assert cli_main(["new-scene", "Bad", "--dir", str(tmp_path / "y")]) == 2


def test_pixels_writes_a_camera_scene_whose_tests_read_the_registration(tmp_path, capsys):
    pkg = tmp_path / "pkg"
    assert cli_main(["new-scene", "pix_mass", "--dir", str(pkg), "--pixels"]) == 0
    generated_tests = (pkg / "tests" / "test_pix_mass.py").read_text()
    assert "(4,)" not in generated_tests and "200" not in generated_tests
    assert 'offsamples="0" shadowsize="0"' in (pkg / "src" / "pix_mass" / "pix_mass.xml").read_text()
    env = dict(os.environ, PYTHONPATH=ROOT)  # the package's pytest config puts src/ on the path
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "import gymnasium as gym, pix_mass; e = gym.make(pix_mass.ENV_ID); o, _ = e.reset(seed=0); "
            "print(o.dtype, o.shape); e.close()",
        ],
        cwd=pkg,
        env=dict(env, PYTHONPATH=os.pathsep.join([str(pkg / "src"), ROOT])),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert probe.stdout.strip() == "uint8 (64, 64, 3)", probe.stdout + probe.stderr
    _assert_generated_tests_pass("tests", pkg, env)


# Issue 35, item 9: the scaffold's tests hold for any scene, its next steps are
# its README's and the guide's, and its spaces make Gymnasium's checker quiet.


def test_the_printed_next_steps_are_the_readmes_and_the_guides(tmp_path, capsys):
    # Before: "pip install -e DIR" (no pytest in the environment) and a bare "pytest".
    pkg = tmp_path / "pkg"
    assert cli_main(["new-scene", "ball_plate", "--dir", str(pkg)]) == 0
    printed = [line.split("#")[0].strip() for line in capsys.readouterr().out.splitlines()]
    assert f'pip install -e "{pkg}[test]"' in printed
    assert f"cd {pkg} && python -m pytest" in printed
    assert not any(c == "pytest" or c.startswith("pytest ") or c.endswith("&& pytest") for c in printed)
    readme = (pkg / "README.md").read_text()
    guide = (Path(__file__).resolve().parents[2] / "docs" / "env-package.md").read_text()
    assert 'pip install -e ".[test]"' in readme and 'pip install -e "my_arm[test]"' in guide
    assert "python -m pytest" in readme and "cd my_arm && python -m pytest" in guide


def test_the_generated_tests_pass_for_a_scene_that_terminates(tmp_path):
    # Before: test_an_episode_runs_to_the_time_limit asserted the episode never
    # terminates, and failed for any scene with a termination condition.
    pkg = tmp_path / "pkg"
    write_package("stop_mass", pkg)
    scene = pkg / "src" / "stop_mass" / "stop_mass_scene.py"
    text = scene.read_text()
    plain = 'return self._obs(), reward, False, {"distance": distance}'
    assert plain in text
    scene.write_text(text.replace(plain, 'return self._obs(), reward, self.data.time > 1.0, {"distance": distance}'))
    env = dict(os.environ, PYTHONPATH=ROOT)  # the package's pytest config puts src/ on the path
    _assert_generated_tests_pass("tests", pkg, env)


def test_the_generated_scene_passes_the_env_checker_without_a_warning(tmp_path):
    # Before: Box(-inf, inf) observations made check_env warn twice.
    pkg = tmp_path / "pkg"
    write_package("quiet_mass", pkg)
    done = subprocess.run(
        [
            sys.executable,
            "-W",
            "error",
            "-c",
            "import gymnasium as gym, quiet_mass\n"
            "from gymnasium.utils.env_checker import check_env\n"
            "e = gym.make(quiet_mass.ENV_ID)\n"
            "check_env(e.unwrapped, skip_render_check=True)\n"
            "print(e.observation_space)\n"
            "e.close()",
        ],
        cwd=tmp_path,
        env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(pkg / "src"), ROOT]), MUJOCO_GL="egl"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr[-3000:]
    assert "inf" not in done.stdout
