"""The layers the tree shows hold at run time: a sim process loads no agent code,
and ``import remoteenv`` stays light."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

AGENT_SIDE = (
    "remoteenv.agent",
    "remoteenv.remote_env",
    "remoteenv.vector_env",
    "remoteenv.integrations.sb3",
    "remoteenv.integrations.frame_dataset",
    "remoteenv.cli",
    "remoteenv.benchmarks",
)


def _loaded_after(statement: str) -> list[str]:
    code = (
        f"import sys, json; {statement}; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] == 'remoteenv')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "statement",
    [
        "import remoteenv.sim",
        "from remoteenv.sim import BaseEnv, RemoteControlledAgent, run_scene",
        "import remoteenv.scenes.cartpole.cartpole_scene",
        "import remoteenv.scenes.reacher.reacher_scene",
        "import remoteenv.sim.process.zygote.fork_server",
    ],
)
def test_sim_side_loads_no_agent_module(statement: str) -> None:
    loaded = _loaded_after(statement)
    assert "remoteenv.sim" in loaded
    agent = [m for m in loaded if m.startswith(AGENT_SIDE)]
    assert not agent, f"{statement!r} loaded agent-side modules: {agent}"
    assert all(m.split(".")[1] in {"sim", "wire", "scenes", "_source_scenes"} for m in loaded if "." in m), loaded


def test_import_remoteenv_registers_ids_and_loads_agent_classes_lazily() -> None:
    loaded = _loaded_after("import remoteenv, gymnasium; assert 'remoteenv/CartPole-v0' in gymnasium.registry")
    assert not [m for m in loaded if m.startswith(AGENT_SIDE)], loaded
    loaded = _loaded_after("import remoteenv; remoteenv.OpenAIRemoteEnv")
    assert "remoteenv.remote_env" in loaded


def test_user_import_paths_keep_working() -> None:
    loaded = _loaded_after(
        "from remoteenv.remote_env import OpenAIRemoteEnv; "
        "from remoteenv.vector_env import RemoteVectorEnv; "
        "from remoteenv.sim import BaseEnv, run_scene, RemoteControlledAgent; "
        "from remoteenv import protocol; protocol.pack; protocol.space_from_wire; "
        "from remoteenv import OpenAIRemoteEnv as A, RemoteVectorEnv as B, RemoteEnvError, Launcher; "
        "assert A is OpenAIRemoteEnv and B is RemoteVectorEnv"
    )
    assert "remoteenv.vector_env" in loaded
