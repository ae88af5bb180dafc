"""Many at once: 4 agent processes launch 8 envs each at the same moment; no
address collides and every env works."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time

from remoteenv.agent.launch.launcher import pid_alive

AGENTS = 4
ENVS_PER_AGENT = 8

AGENT = textwrap.dedent(
    """
    import json, sys
    from remoteenv import OpenAIRemoteEnv, scene_path
    agent, n, transport = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    # 32 sims start at once on 2 cores: startup may take a while.
    envs = [OpenAIRemoteEnv(scene_path("cartpole"), transport=transport, seed=agent * 100 + i,
                            startup_timeout=400.0, timeout=300.0) for i in range(n)]
    out = []
    for i, env in enumerate(envs):
        obs, _ = env.reset(seed=agent * 100 + i)
        rewards = [env.step(k % 2)[1] for k in range(3)]
        out.append({"endpoint": env.launcher.sims[0].endpoint, "pid": env.pid,
                    "workdir": env.launcher.workdir, "obs0": obs.tolist(), "rewards": rewards})
    for env in envs:
        env.close()
    print(json.dumps(out), flush=True)
    """
)


def test_four_agents_with_eight_envs_each_at_once():
    env = {**os.environ, "MUJOCO_GL": "egl"}
    agents = [
        subprocess.Popen(
            [sys.executable, "-c", AGENT, str(a), str(ENVS_PER_AGENT), "ipc" if a % 2 == 0 else "tcp"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for a in range(AGENTS)
    ]
    results = []
    try:
        for a, proc in enumerate(agents):
            out, err = proc.communicate(timeout=500)
            assert proc.returncode == 0, f"agent {a} failed:\n{err[-3000:]}"
            results.append(json.loads(out.strip().splitlines()[-1]))
    finally:
        for proc in agents:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    envs = [e for r in results for e in r]
    assert len(envs) == AGENTS * ENVS_PER_AGENT
    endpoints = [e["endpoint"] for e in envs]
    assert len(set(endpoints)) == len(endpoints), "two sims shared an address"
    assert len({e["workdir"] for e in envs}) == len(envs)
    assert len({e["pid"] for e in envs}) == len(envs)
    for e in envs:
        assert e["rewards"] == [1.0, 1.0, 1.0] and len(e["obs0"]) == 4
    # Different seeds, different starts: nobody talked to someone else's sim.
    assert len({tuple(e["obs0"]) for e in envs}) == len(envs)
    # Closed envs leave nothing behind.
    time.sleep(0.2)
    for e in envs:
        assert not pid_alive(e["pid"]) and not os.path.exists(e["workdir"])
