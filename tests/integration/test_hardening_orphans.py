"""Issue 10, item 9: a sim exits within a second of its agent's death even
while its main thread holds the interpreter lock in a long C call (there its
own watch thread cannot run; the orphan guard process ends it).

Timing is the behaviour under test here. The bound is the issue's 1 s plus a
margin for a loaded 2-core machine; the measured time is printed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes")
COSTLY = os.path.join(SCENES, "hardening_scene.py")
ORPHAN_EXIT_S = 1.5

AGENT = textwrap.dedent(
    """
    import json, sys, time
    from remoteenv import OpenAIRemoteEnv
    env = OpenAIRemoteEnv(sys.argv[1], gil_items=10**10, startup_timeout=120.0)
    env.reset(seed=0)
    env.unwrapped._conn.send("step", action=0)  # the sim now holds its GIL for minutes
    time.sleep(0.5)
    print(json.dumps([env.pid, env.launcher.workdir]), flush=True)
    time.sleep(600)
    """
)


def test_a_sim_holding_its_gil_exits_within_a_second_of_its_agents_death(pid_alive, wait_gone):
    agent = subprocess.Popen(
        [sys.executable, "-c", AGENT, COSTLY], stdout=subprocess.PIPE, text=True, env={**os.environ, "MUJOCO_GL": "egl"}
    )
    pid = None
    try:
        line = agent.stdout.readline()
        assert line, f"agent exited early with code {agent.wait()}"
        pid, workdir = json.loads(line)
        with open(f"/proc/{pid}/stat") as f:
            assert f.read().rsplit(")", 1)[1].split()[0] == "R", "the sim should be busy in its step"
        agent.kill()
        agent.wait()
        killed = time.monotonic()
        gone = wait_gone(pid, 10.0)
        took = time.monotonic() - killed
        print(f"sim holding its GIL exited {took:.3f} s after its agent was SIGKILLed")
        assert gone and took < ORPHAN_EXIT_S
        deadline = time.monotonic() + 2.0
        while os.path.exists(workdir) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not os.path.exists(workdir), f"left behind: {os.listdir(workdir)}"
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        if pid is not None and pid_alive(pid):
            os.kill(pid, signal.SIGKILL)
