"""Issue 28, item 4: every bad argument gives a clear error, never a traceback.

Each case runs ``python -m remoteenv ...`` and checks the exit status, that
stderr holds no traceback, and that it is one line naming what is wrong
(argparse's own errors included: the usage is named, not printed)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

SWEEP = ["latency-sweep", "remoteenv/CartPole-v0", "--policy", "cartpole_discrete", "--no-plot", "--episodes", "1"]
HUGE = str(2**70)
DEMO = ["demo", "cartpole", "--episodes", "1", "--env-kwargs"]


@pytest.fixture
def files(tmp_path):
    (tmp_path / "plain.py").write_text("x = 1\n")
    (tmp_path / "notes.txt").write_text("hello\n")
    (tmp_path / "policy.pt").write_bytes(b"not a TorchScript archive\n")
    return tmp_path


CASES = {
    "sweep-delays-99999": (SWEEP + ["--delays", "99999"], "--delays"),
    "sweep-delays-2**70": (SWEEP + ["--delays", HUGE], "--delays"),
    "sweep-seeds-2**70": (SWEEP + ["--delays", "0", "--seeds", HUGE], "--seeds"),
    "sweep-action-history-10**7": (SWEEP + ["--delays", "0", "--action-history", str(10**7)], "--action-history"),
    "sweep-env-kwargs": (SWEEP + ["--delays", "0", "--env-kwargs", '{"bogus": 1}'], "bogus"),
    "sweep-policy-not-torchscript": (
        ["latency-sweep", "remoteenv/CartPole-v0", "--policy", "{tmp}/policy.pt", "--no-plot", "--delays", "0"],
        "not a TorchScript file",
    ),
    "sweep-unknown-id": (
        ["latency-sweep", "nosuch/Id-v0", "--policy", "cartpole_discrete", "--no-plot", "--delays", "0"],
        "nosuch/Id-v0",
    ),
    "demo-non-scene": (["demo", "{tmp}/plain.py"], "not a scene script"),
    "demo-non-python": (["demo", "{tmp}/notes.txt"], "not a Python file"),
    "demo-no-such-module": (["demo", "nosuchmodule:id"], "nosuchmodule"),
    "demo-seed-2**70": (["demo", "cartpole", "--seed", HUGE], "--seed"),
    "demo-seed-not-a-number": (["demo", "cartpole", "--seed", "2**70"], "--seed"),
    "sweep-episodes-not-a-number": (SWEEP[:-1] + ["x", "--delays", "0"], "--episodes"),
    "unknown-command": (["nosuchcommand"], "nosuchcommand"),
    # Issue 35, item 7: scene kwargs the scene refuses, bench and study bounds.
    "demo-env-kwargs-unknown-key": (DEMO + ['{"bogus": 1}'], "unexpected keyword argument 'bogus'"),
    "demo-env-kwargs-reacher-unknown-key": (
        ["demo", "reacher", "--episodes", "1", "--env-kwargs", '{"bogus": 1}'],
        "unexpected keyword argument 'bogus'",
    ),
    "demo-env-kwargs-nan-image-size": (DEMO + ['{"obs_mode": "pixels", "image_size": NaN}'], "must be an int"),
    "demo-env-kwargs-nan-continuous": (DEMO + ['{"continuous": NaN}'], "continuous must be True or False"),
    "demo-env-kwargs-obs-mode": (DEMO + ['{"obs_mode": "pixles"}'], "obs_mode must be one of"),
    "demo-env-kwargs-camera-quality": (
        DEMO + ['{"obs_mode": "pixels", "camera_quality": "no"}'],
        "camera quality must be True or False",
    ),
    "demo-env-kwargs-100-kB": (DEMO + ['{"obs_mode": "' + "x" * 100_000 + '"}'], "more than the 65536"),
    "bench-pixels-cases-100000x1": (["bench", "--pixels", "--pixels-cases", "100000x1"], "--pixels-cases 100000x1"),
    "bench-pixels-cases-4097x1": (["bench", "--pixels", "--pixels-cases", "4097x1"], "--pixels-cases 4097x1"),
    "bench-pixels-cases-64x100000": (["bench", "--pixels", "--pixels-cases", "64x100000"], "ask for at most"),
    "bench-pixels-duration-nan": (["bench", "--pixels", "--pixels-duration", "nan"], "--pixels-duration"),
    "bench-pixels-duration-inf": (["bench", "--pixels", "--pixels-duration", "inf"], "--pixels-duration"),
    "bench-pixels-rounds-10**7": (["bench", "--pixels", "--pixels-rounds", "10000000"], "--pixels-rounds"),
    "study-delays-100000": (["latency-study", "--delays", "1,2,100000", "--out", "{tmp}/study"], "--delays"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_bad_argument_is_one_clear_line_not_a_traceback(files, case):
    argv, expected = CASES[case]
    argv = [a.replace("{tmp}", str(files)) for a in argv]
    if "latency-sweep" in argv:
        argv += ["--out", str(files / "out")]
    done = subprocess.run(
        [sys.executable, "-m", "remoteenv", *argv],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MUJOCO_GL": "egl"},
        cwd=files,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode != 0, done.stdout[-1000:]
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    assert len(lines) == 1 and expected in lines[0], done.stderr[-3000:]


def test_the_command_line_parser_imports_no_trainer_or_plot_package(tmp_path):
    """``python -m remoteenv`` builds the parser of every command (and of every
    benchmark's arguments) before it reads one. torch, Stable-Baselines3,
    matplotlib, Ray, TorchRL and EnvPool are imported by the commands that use
    them, when they run, so that ``--help`` or a mistyped argument answers at once."""
    code = (
        "import sys\n"
        "from remoteenv.cli import COMMANDS, main\n"
        "for command in COMMANDS:\n"
        "    try:\n"
        "        main([command, '--help'])\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = ('torch', 'stable_baselines3', 'matplotlib', 'ray', 'torchrl', 'envpool')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    # Run from tmp_path: the installed package is the one imported.
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.splitlines()[-1] == "[]", done.stdout[-2000:]
