"""Issue 28, item 5: ``make test`` runs the unit, integration and Ray suites
even when one fails, and fails if any did, naming which. The Makefile runs
from a copy in a temporary folder with stand-in suites (scripts that log
their call) and the set-up skipped (``TEST_SETUP=``): nothing real is built or run.
The set-up's wiring is read from a dry run (``make -n``)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SUITE = """#!/bin/sh
echo "$0 $*" >> "{log}"
case "$*" in *{failing}*) exit 1;; esac
exit 0
"""


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
@pytest.mark.parametrize("failing", ["unit", "integration", "ray", "none"])
def test_make_test_runs_every_suite_and_names_the_ones_that_failed(tmp_path, failing):
    log = tmp_path / "log"
    venv_bin = tmp_path / "venv" / "bin"
    venv_bin.mkdir(parents=True)
    for script in (venv_bin / "pytest", tmp_path / "ray-suite"):
        script.write_text(SUITE.format(log=log, failing="tests/" + failing if failing != "ray" else "ray"))
        script.chmod(0o755)
    shutil.copy(ROOT / "Makefile", tmp_path / "Makefile")
    done = subprocess.run(
        ["make", "-C", str(tmp_path), "test", "TEST_SETUP="]
        + [f"VENV={tmp_path / 'venv'}", f"RAY_SUITE={tmp_path / 'ray-suite'} ray"],
        capture_output=True,
        text=True,
        timeout=60,
        env={k: v for k, v in os.environ.items() if not k.startswith("MAKE")},
    )
    ran = log.read_text().splitlines()
    # The integration suite runs twice: two tests at a time, then the serial ones alone.
    assert [line.split()[-1] for line in ran] == ["tests/unit", "tests/integration", "tests/integration", "ray"], ran
    assert "-m not serial" in ran[1] and "-n" in ran[1].split() and "-m serial" in ran[2], ran
    if failing == "none":
        assert done.returncode == 0, done.stderr
    else:
        assert done.returncode != 0
        assert f"these suites failed: {failing}" in done.stderr, done.stderr


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_test_sets_up_the_ray_venv_beside_the_main_one_before_any_suite(tmp_path):
    for name in ("Makefile", "pyproject.toml"):
        shutil.copy(ROOT / name, tmp_path / name)
    dry = subprocess.run(
        ["make", "-n", "-C", str(tmp_path), "test", f"VENV={tmp_path / 'venv'}", "RAY_SUITE=ray-suite"],
        capture_output=True,
        text=True,
        timeout=60,
        env={k: v for k, v in os.environ.items() if not k.startswith("MAKE")},
    )
    assert dry.returncode == 0, dry.stderr
    lines = dry.stdout.splitlines()
    setup = next(i for i, line in enumerate(lines) if "--output-sync" in line)
    assert "-j2" in lines[setup].split() and lines[setup].split()[-3:] == ["install", "lint", "ray-venv"], lines[setup]
    venv = next(i for i, line in enumerate(lines) if line.endswith(f"-m venv {tmp_path / 'venv'}"))
    ray_venv = lines.index("ray-suite --setup")
    first_suite = next(i for i, line in enumerate(lines) if "tests/unit" in line)
    assert setup < venv < first_suite and setup < ray_venv < first_suite, lines
