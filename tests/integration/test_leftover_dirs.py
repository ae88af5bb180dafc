"""Issue 19, item 11: no private dir is left behind when the agent's process
is terminated (SIGTERM, as ``multiprocessing.Pool.terminate`` does) or killed
(SIGKILL) while it closes its env.

The window is the launcher's ``stop_all``: the sim has been told to stop (so
it does not tidy up for an agent it still sees alive), and the dir is not yet
removed. The tests stop the agent right there, deterministically: its
``shutil.rmtree`` is replaced by one that says so and waits. Every agent runs
with ``TMPDIR`` in the test's own dir, so only its dirs are looked at.

Timing is part of the behaviour (the orphan guard tidies up after the
agent's death): the dir must be gone within 10 s, a bound that covers the
guard's 0.5 s grace and a loaded 2-core machine.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

GONE_WITHIN_S = 10.0

#: Replaces rmtree in the launcher's stop_all: announce the removal (a line on
#: stdout, or a marker file) and wait to be terminated.
STALL = textwrap.dedent(
    """
    import os, sys, time
    import remoteenv.agent.launch.sim_process as sim_process

    def stall(marker=None):
        def rmtree(path, *args, **kwargs):
            if marker:
                open(marker, "w").close()
            print("removing", path, flush=True)
            time.sleep(600)
        sim_process.shutil.rmtree = rmtree
    """
)

AGENT = STALL + textwrap.dedent(
    """
    import gymnasium as gym
    import remoteenv
    env = gym.make("remoteenv/CartPole-v0")
    env.reset(seed=0)
    stall()
    env.close()
    """
)

POOL_AGENT = STALL + textwrap.dedent(
    """
    import multiprocessing
    import gymnasium as gym
    import remoteenv

    def work(env, marker):
        env.reset(seed=0)  # this worker's own env: unpickling built it with a fresh sim
        stall(marker)
        env.close()

    if __name__ == "__main__":
        method, marker = sys.argv[1], sys.argv[2]
        env = gym.make("remoteenv/CartPole-v0")
        pool = multiprocessing.get_context(method).Pool(1)
        pool.apply_async(work, (env, marker))
        deadline = time.monotonic() + 120
        while not os.path.exists(marker) and time.monotonic() < deadline:
            time.sleep(0.02)
        pool.terminate()  # SIGTERM to the worker, in the middle of its env's close
        pool.join()
        env.close()
        print("terminated" if os.path.exists(marker) else "the worker never closed its env", flush=True)
    """
)


def _left(tmp: Path, deadline_s: float = GONE_WITHIN_S) -> list[str]:
    """The private dirs under ``tmp`` still there after up to ``deadline_s`` seconds."""
    deadline = time.monotonic() + deadline_s
    while True:
        left = sorted(str(p) for p in tmp.glob("remoteenv-*"))
        if not left or time.monotonic() > deadline:
            return [f"{p}: {sorted(os.listdir(p))}" for p in left if os.path.isdir(p)]
        time.sleep(0.05)


def _env(tmp: Path) -> dict[str, str]:
    return {**os.environ, "TMPDIR": str(tmp), "MUJOCO_GL": "egl"}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_an_agent_stopped_while_it_closes_its_env_leaves_no_private_dir(tmp_path, sig):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    agent = subprocess.Popen([sys.executable, "-c", AGENT], stdout=subprocess.PIPE, text=True, env=_env(tmp))
    try:
        line = agent.stdout.readline()  # type: ignore[union-attr]
        assert line.startswith("removing"), f"the agent exited early ({agent.wait()})"
        agent.send_signal(sig)
        agent.wait(timeout=30)
        stopped = time.monotonic()
        left = _left(tmp)
        print(f"{sig.name} during close: dirs gone after {time.monotonic() - stopped:.2f} s, left {left}")
        assert not left
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        agent.stdout.close()  # type: ignore[union-attr]


@pytest.mark.parametrize("method", ["spawn", "fork"])
def test_a_pool_terminated_while_its_worker_closes_a_pickled_env_leaves_no_private_dir(tmp_path, method):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    script = tmp_path / "pool_agent.py"
    script.write_text(POOL_AGENT)
    done = subprocess.run(
        [sys.executable, str(script), method, str(tmp_path / "closing")],
        capture_output=True,
        text=True,
        timeout=300,
        env=_env(tmp),
    )
    assert "terminated" in done.stdout, (done.stdout, done.stderr[-2000:])
    left = _left(tmp)
    print(f"pool ({method}) terminated while its worker closed its env: left {left}")
    assert not left
