"""``python -m remoteenv new-scene`` writes a package that installs with pip and passes its own tests."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from remoteenv.cli import main as cli_main
from remoteenv.cli.new_scene import write_package

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


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
    tests = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(pkg / "tests")],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert tests.returncode == 0, tests.stdout + tests.stderr
    assert "3 passed" in tests.stdout


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
