"""The commands check their arguments before they start work: bad numbers,
unwritable output paths and missing optional packages are refused at once
with a clear message, and the latency sweep keeps every result it ran.

No sim is started: where a command would start one, the function that does
is replaced by one that fails the test if it is called.
"""

from __future__ import annotations

import csv
import json
import os
import sys

import numpy as np
import pytest

from remoteenv.cli import COMMANDS, latency_sweep, main

SWEEP = ["latency-sweep", "cartpole", "--policy", "cartpole_continuous", "--no-plot"]


def _no_sims(*args, **kwargs):
    raise AssertionError("the command started work before checking its arguments")


class _FakeEnv:
    """Three steps per episode, obs of CartPole's shape; no process."""

    dt = 0.02

    def __init__(self) -> None:
        self.unwrapped = self
        self.t = 0

    def reset(self, seed=None):
        self.t = 0
        return np.zeros(4, np.float32), {}

    def step(self, action):
        self.t += 1
        return np.zeros(4, np.float32), 1.0, self.t >= 3, False, {}

    def close(self) -> None:
        pass


@pytest.mark.parametrize("timeout", ["inf", "-inf", "nan", "-1", "0", "1e400", "1e300", "ten"])
def test_check_refuses_a_timeout_that_is_not_a_finite_positive_number(tmp_path, capsys, timeout):
    with pytest.raises(SystemExit) as exc:
        main(["check", str(tmp_path / "launch.json"), "--timeout", timeout])
    assert exc.value.code == 2
    assert "--timeout" in capsys.readouterr().err


@pytest.mark.parametrize("steps", ["-1", "0"])
def test_latency_sweep_refuses_a_max_steps_that_is_not_positive(tmp_path, monkeypatch, capsys, steps):
    monkeypatch.setattr(latency_sweep, "make_env", _no_sims)
    with pytest.raises(SystemExit):
        main([*SWEEP, "--max-steps", steps, "--out", str(tmp_path / "out")])
    assert "--max-steps: must be a positive integer" in capsys.readouterr().err


def test_demo_refuses_a_max_steps_that_is_not_positive(monkeypatch, capsys):
    from remoteenv.cli import demo

    monkeypatch.setattr(demo, "make_env", _no_sims)
    with pytest.raises(SystemExit):
        main(["demo", "cartpole", "--max-steps", "-1"])
    assert "--max-steps: must be a positive integer" in capsys.readouterr().err


def test_latency_sweep_fails_at_once_on_an_unwritable_out(tmp_path, monkeypatch):
    monkeypatch.setattr(latency_sweep, "make_env", _no_sims)
    out = tmp_path / "out"
    (out / "sweep.csv").mkdir(parents=True)  # unwritable for root too
    with pytest.raises(SystemExit, match="cannot write the results into --out"):
        main([*SWEEP, "--out", str(out)])
    a_file = tmp_path / "a-file"
    a_file.write_text("")
    with pytest.raises(SystemExit, match="cannot write the results into --out"):
        main([*SWEEP, "--out", str(a_file)])


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into a 0500 dir")
def test_latency_sweep_fails_at_once_on_a_read_only_out(tmp_path, monkeypatch):
    monkeypatch.setattr(latency_sweep, "make_env", _no_sims)
    out = tmp_path / "ro"
    out.mkdir(mode=0o500)
    with pytest.raises(SystemExit, match="cannot write the results into --out"):
        main([*SWEEP, "--out", str(out)])


def test_latency_sweep_keeps_the_rows_of_a_sweep_cut_short(tmp_path, monkeypatch):
    made = []

    def make_env(args, delay):
        made.append(delay)
        if delay == 2:
            raise RuntimeError("the third point fails")
        return _FakeEnv()

    monkeypatch.setattr(latency_sweep, "make_env", make_env)
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="third point"):
        main([*SWEEP, "--delays", "0,1,2", "--seeds", "0", "--episodes", "2", "--out", str(out)])
    assert made == [0, 1, 2]
    with open(out / "sweep.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["delay"], r["episode"], r["length"]) for r in rows] == [
        ("0", "0", "3"),
        ("0", "1", "3"),
        ("1", "0", "3"),
        ("1", "1", "3"),
    ]
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["complete"] is False and [s["delay"] for s in doc["summary"]] == [0, 1] and len(doc["rows"]) == 4


def test_launch_fails_on_an_unwritable_out_before_starting_sims(tmp_path, monkeypatch):
    import remoteenv.agent.launch.launcher

    monkeypatch.setattr(remoteenv.agent.launch.launcher, "Launcher", _no_sims)
    with pytest.raises(SystemExit, match="cannot write --out"):
        main(["launch", "cartpole", "--out", str(tmp_path / "no-such-dir" / "launch.json")])
    with pytest.raises(SystemExit, match="is a directory"):
        main(["launch", "cartpole", "--out", str(tmp_path)])


def test_launch_refuses_env_kwargs_that_are_not_a_json_map(tmp_path, monkeypatch):
    import remoteenv.agent.launch.launcher

    monkeypatch.setattr(remoteenv.agent.launch.launcher, "Launcher", _no_sims)
    for text in ("{not json", "[1, 2]"):
        with pytest.raises(SystemExit, match="--env-kwargs must be a JSON map"):
            main(["launch", "cartpole", "--env-kwargs", text, "--out", str(tmp_path / "l.json")])


def test_a_missing_plot_package_is_named_with_its_extra_before_the_sweep(tmp_path, monkeypatch):
    monkeypatch.setattr(latency_sweep, "make_env", _no_sims)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib now fails
    argv = [a for a in SWEEP if a != "--no-plot"]
    with pytest.raises(SystemExit, match=r"needs matplotlib, which is not installed: pip install 'remoteenv\[torch\]'"):
        main([*argv, "--out", str(tmp_path / "out")])


def test_the_sweep_runs_without_tqdm(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(latency_sweep, "make_env", lambda args, delay: _FakeEnv())
    monkeypatch.setitem(sys.modules, "tqdm", None)
    assert main([*SWEEP, "--delays", "0", "--seeds", "0", "--episodes", "2", "--out", str(tmp_path / "o")]) == 0
    assert "latency sweep: 2/2 episodes" in capsys.readouterr().out


def test_demo_record_without_moviepy_names_the_video_extra(tmp_path, monkeypatch):
    from remoteenv.cli import demo

    monkeypatch.setattr(demo, "make_env", _no_sims)
    monkeypatch.setitem(sys.modules, "moviepy", None)
    with pytest.raises(SystemExit, match=r"demo --record needs moviepy.*remoteenv\[video\]"):
        main(["demo", "cartpole", "--record", str(tmp_path)])


def test_an_optional_package_missing_deep_in_a_command_gets_the_same_message(monkeypatch, capsys):
    from remoteenv.cli import keys_command

    def run(args):
        raise ModuleNotFoundError("No module named 'envpool'", name="envpool")

    monkeypatch.setattr(keys_command, "run", run)
    assert main(["keys", "somewhere"]) == 2
    assert "python -m remoteenv keys needs envpool, which is not installed: pip install 'remoteenv[bench]'" in (
        capsys.readouterr().err
    )


def test_a_missing_module_that_is_no_optional_package_still_raises(monkeypatch):
    from remoteenv.cli import keys_command

    def run(args):
        raise ModuleNotFoundError("No module named 'scene_helpers'", name="scene_helpers")

    monkeypatch.setattr(keys_command, "run", run)
    with pytest.raises(ModuleNotFoundError):
        main(["keys", "somewhere"])


def test_latency_sweep_runs_a_plain_python_controller_from_a_module_or_a_file(tmp_path, monkeypatch):
    monkeypatch.setattr(latency_sweep, "make_env", lambda args, delay: _FakeEnv())
    monkeypatch.setattr(latency_sweep, "checked_env", lambda args, delay: _FakeEnv())
    script = tmp_path / "my_controller.py"
    script.write_text(
        "import numpy as np\n"
        "calls = []\n"
        "def policy(obs):\n"
        "    calls.append(1)\n"
        "    return np.zeros(1, np.float32)\n"
        "class Remembering:\n"
        "    resets = 0\n"
        "    def reset(self):\n"
        "        Remembering.resets += 1\n"
        "    def __call__(self, obs):\n"
        "        return np.zeros(1, np.float32)\n"
    )
    for controller in [
        "remoteenv.controllers:cartpole_continuous",
        str(script),
        f"{script}:Remembering",
    ]:
        out = tmp_path / controller.replace("/", "_").replace(":", "_")
        argv = ["latency-sweep", "cartpole", "--controller", controller, "--no-plot", "--delays", "0,1"]
        assert main([*argv, "--episodes", "2", "--seeds", "0", "--out", str(out)]) == 0
        assert len((out / "sweep.csv").read_text().splitlines()) == 1 + 2 * 2
        assert "controller" in (out / "sweep.json").read_text()


@pytest.mark.parametrize(
    ("controller", "message"),
    [
        ("no_such_module_xyz:f", "cannot import 'no_such_module_xyz'"),
        ("remoteenv.controllers:nothing_here", "has no 'nothing_here'"),
        ("remoteenv.controllers:CARTPOLE_DT", "is not callable"),
        ("missing.py", "'missing.py' is not a file"),
        ("remoteenv.controllers", "must be module:function or a .py file"),
    ],
)
def test_latency_sweep_names_a_controller_it_cannot_load_in_one_line(tmp_path, monkeypatch, controller, message):
    monkeypatch.setattr(latency_sweep, "make_env", _no_sims)
    monkeypatch.setattr(latency_sweep, "checked_env", _no_sims)
    with pytest.raises(SystemExit, match=message) as exc:
        main(["latency-sweep", "cartpole", "--controller", controller, "--no-plot", "--out", str(tmp_path / "o")])
    assert "\n" not in str(exc.value)


def test_every_command_help_ends_its_sentences(capsys):
    """No help description stops mid-sentence (ends with ':') or describes the rounded replay."""
    for command in COMMANDS:  # every command the parser has, a new one included
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = capsys.readouterr().out
        description = text.split("\n\npositional arguments:")[0].split("\n\noptions:")[0].strip()
        assert not description.endswith(":"), (command, description[-80:])
        assert "replays the recordings in\nlock-step" not in text and "in lock-step, and compares" not in text
