"""An agent whose TMPDIR is too long for a Unix socket's path still starts its
sims (their private dir made in a shorter base) and leaves nothing behind."""

from __future__ import annotations

import json
import os
import subprocess
import sys

AGENT = r"""
import json, os, sys, tempfile
import gymnasium as gym, numpy as np
import remoteenv
env = gym.make("remoteenv/Reacher-v0")
env.reset(seed=0)
env.step(env.action_space.sample())
single = env.unwrapped._session.group._state.workdir
env.close()
vec = gym.make_vec("remoteenv/Reacher-v0", 3, vectorization_mode="vector_entry_point", envs_per_process=1)
vec.reset(seed=0)
vec.step(np.zeros((3, 2), np.float32))
vec.close()
print(json.dumps({"tempdir": tempfile.gettempdir(), "single": single}))
"""


def test_a_long_tmpdir_moves_the_private_dir_and_leaves_nothing(agent_tmpdir):
    long = agent_tmpdir / ("d" * 90)
    long.mkdir()
    runtime = agent_tmpdir / "run"
    runtime.mkdir(mode=0o700)
    env = {**os.environ, "TMPDIR": str(long), "XDG_RUNTIME_DIR": str(runtime), "MUJOCO_GL": "egl"}
    done = subprocess.run([sys.executable, "-c", AGENT], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["tempdir"] == str(long)
    assert os.path.dirname(out["single"]) == str(runtime)
    assert not os.path.exists(out["single"])
    assert os.listdir(runtime) == []
    assert os.listdir(long) == []
