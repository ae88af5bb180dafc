"""RLlib's env creators (remoteenv.integrations.rllib.EnvCreator) build envs in processes
that never imported remoteenv or the env's package; Ray itself is not needed
here (tests/ray trains with them)."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys

from remoteenv.cli.new_scene import write_package
from remoteenv.integrations.rllib import EnvCreator
from remoteenv.registration import find_spec, remote_env_ids

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

CHILD = """
import pickle, sys
modules = set(sys.modules)
creator = pickle.loads(sys.stdin.buffer.read())
single = creator({"seed": 0})
obs, _ = single.reset(seed=0)
print("single", type(single.unwrapped).__name__, obs.shape, single.spec.max_episode_steps)
single.close()
vector = creator({"seed": 0, "num_envs": 2})
obs, _ = vector.reset(seed=0)
print("vector", type(vector).__name__, obs.shape, vector.metadata["autoreset_mode"].name)
vector.close()
print("had", sorted(m for m in ("remoteenv", "ball_plate") if m in modules))
"""


def _run_in_a_fresh_process(creator: EnvCreator, env: dict[str, str]) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-c", CHILD],
        input=pickle.dumps(creator),
        env=env,
        capture_output=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr.decode()[-3000:]
    return out.stdout.decode().splitlines()


def test_a_shipped_id_in_a_process_that_never_imported_remoteenv():
    assert "remoteenv/CartPole-v0" in remote_env_ids()
    lines = _run_in_a_fresh_process(EnvCreator(find_spec("remoteenv/CartPole-v0")), dict(os.environ, PYTHONPATH=ROOT))
    assert lines == [
        "single OpenAIRemoteEnv (4,) 500",
        "vector RemoteVectorEnv (2, 4) NEXT_STEP",
        "had []",
    ]


def test_an_env_package_the_worker_cannot_even_import(tmp_path, monkeypatch):
    write_package("ball_plate", tmp_path / "ball_plate")
    monkeypatch.syspath_prepend(str(tmp_path / "ball_plate" / "src"))
    try:
        spec = find_spec("ball_plate:ball_plate/BallPlate-v0")
        assert "ball_plate/BallPlate-v0" in remote_env_ids()
        # The child's path has remoteenv only: the creator carries the spec (the scene script's path).
        lines = _run_in_a_fresh_process(EnvCreator(spec), dict(os.environ, PYTHONPATH=ROOT))
    finally:
        import gymnasium

        gymnasium.registry.pop("ball_plate/BallPlate-v0", None)
        sys.modules.pop("ball_plate", None)
    assert lines == ["single OpenAIRemoteEnv (4,) 200", "vector RemoteVectorEnv (2, 4) NEXT_STEP", "had []"]


def test_importing_the_adapter_does_not_import_ray():
    out = subprocess.run(
        [sys.executable, "-c", "import sys, remoteenv.integrations.rllib; print('ray' in sys.modules)"],
        env=dict(os.environ, PYTHONPATH=ROOT),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.stdout.strip() == "False", out.stderr
