"""Issue 19, item 11: no private dir is left behind when the agent's process
is terminated (SIGTERM, as ``multiprocessing.Pool.terminate`` does) or killed
(SIGKILL) while it closes its env.

The window is the launcher's ``stop_all``: the sim has been told to stop (so
it does not tidy up for an agent it still sees alive), and the dir is not yet
removed. The tests stop the agent right there, deterministically: its
dir removal (``remove_dir``) is replaced by one that says so and waits. Every agent runs
with ``TMPDIR`` in the test's own dir, so only its dirs are looked at.

Timing is part of the behaviour (the orphan guard tidies up after the
agent's death): the dir must be gone within 10 s, a bound that covers the
guard's 0.5 s grace and a loaded 2-core machine.
"""

from __future__ import annotations

import inspect
import json
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

GONE_WITHIN_S = 10.0

#: Replaces the dir removal in the launcher's stop_all: announce it (a line on
#: stdout, or a marker file) and wait to be terminated.
STALL = textwrap.dedent(
    """
    import os, sys, time
    import remoteenv.agent.launch.sim_process as sim_process

    def stall(marker=None):
        def remove_dir(path, *args, **kwargs):
            if marker:
                open(marker, "w").close()
            print("removing", path, flush=True)
            time.sleep(600)
        sim_process.remove_dir = remove_dir
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
def test_an_agent_stopped_while_it_closes_its_env_leaves_no_private_dir(tmp_path, agent_tmpdir, sig):
    tmp = agent_tmpdir
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
def test_a_pool_terminated_while_its_worker_closes_a_pickled_env_leaves_no_private_dir(tmp_path, agent_tmpdir, method):
    tmp = agent_tmpdir
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


# Issue 28, item 1: an agent that dies before its sim exists (its zygote still
# importing) leaves nothing behind: its dir reaper removes the private dir and
# the zygote, which watches the agent from its first instruction, exits.
# The bound is 1 s; 1.5 s leaves a margin for a loaded 2-core machine.
NOTHING_WITHIN_S = 1.5

EARLY_AGENT = textwrap.dedent(
    """
    import gymnasium as gym
    import remoteenv
    env = gym.make("remoteenv/CartPole-v0")
    """
)


def _children(parent: int, marker: bytes) -> list[int]:
    """Pids of ``parent``'s children whose command line holds ``marker``
    (the early pool agent below runs this function's own source)."""
    found = []
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmd = f.read()
        except (OSError, ValueError, IndexError):
            continue
        if ppid == parent and marker in cmd:
            found.append(int(entry))
    return found


#: A fork-context pool whose worker makes an env; the pool is terminated as soon
#: as the worker's zygote process exists. Prints the pids it saw and when.
EARLY_POOL_AGENT = textwrap.dedent(
    """
    import json, multiprocessing, os, sys, time
    import gymnasium as gym
    import remoteenv

    def work():
        gym.make("remoteenv/CartPole-v0")
    """
)
EARLY_POOL_AGENT += (
    "\n\n"
    + inspect.getsource(_children)
    + textwrap.dedent(
        """

    if __name__ == "__main__":
        pool = multiprocessing.get_context("fork").Pool(1)
        worker = pool.apply(os.getpid)
        pool.apply_async(work)
        deadline = time.monotonic() + 60
        zygotes = []
        while not zygotes and time.monotonic() < deadline:
            zygotes = _children(worker, b"zygote/start.py")
        reapers = _children(worker, b"dir_reaper_main.py")
        killed = time.monotonic()
        pool.terminate()  # SIGTERM to the worker while its zygote imports
        pool.join()
        print(json.dumps({"killed": killed, "pids": zygotes + reapers, "zygotes": len(zygotes)}), flush=True)
    """
    )
)


def _nothing_left(tmp: Path, pids: list[int], pid_alive, since: float) -> tuple[float, list[str], list[int]]:
    """Seconds from ``since`` until no private dir is under ``tmp`` and none of
    ``pids`` runs (up to GONE_WITHIN_S), and what was left then."""
    deadline = since + GONE_WITHIN_S
    while True:
        dirs = sorted(str(p) for p in tmp.glob("remoteenv-*"))
        alive = [pid for pid in pids if pid_alive(pid)]
        now = time.monotonic()
        if (not dirs and not alive) or now > deadline:
            return now - since, dirs, alive
        time.sleep(0.01)


def _kill_all(pids: list[int], pid_alive) -> None:
    for pid in pids:
        if pid_alive(pid):
            os.kill(pid, signal.SIGKILL)


def test_an_agent_killed_as_its_zygote_starts_leaves_nothing_within_a_second(tmp_path, agent_tmpdir, pid_alive):
    tmp = agent_tmpdir
    agent = subprocess.Popen([sys.executable, "-c", EARLY_AGENT], env=_env(tmp))
    pids: list[int] = []
    try:
        deadline = time.monotonic() + 60
        zygotes: list[int] = []
        while not zygotes and agent.poll() is None and time.monotonic() < deadline:
            zygotes = _children(agent.pid, b"zygote/start.py")
        assert zygotes, f"no zygote seen (the agent exited with {agent.poll()})"
        pids = zygotes + _children(agent.pid, b"dir_reaper_main.py")
        agent.kill()
        killed = time.monotonic()
        agent.wait()
        took, dirs, alive = _nothing_left(tmp, pids, pid_alive, killed)
        print(f"agent SIGKILLed at its zygote's start: nothing left after {took:.3f} s (dirs {dirs}, pids {alive})")
        assert not dirs and not alive
        assert took < NOTHING_WITHIN_S
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        _kill_all(pids, pid_alive)


def test_a_fork_pool_terminated_as_its_workers_zygote_starts_leaves_nothing_within_a_second(
    tmp_path, agent_tmpdir, pid_alive
):
    tmp = agent_tmpdir
    script = tmp_path / "early_pool_agent.py"
    script.write_text(EARLY_POOL_AGENT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=_env(tmp))
    seen = json.loads(done.stdout.strip().splitlines()[-1]) if done.stdout.strip() else {}
    pids = seen.get("pids", [])
    try:
        assert seen.get("zygotes") == 1, (done.stdout, done.stderr[-2000:])
        took, dirs, alive = _nothing_left(tmp, pids, pid_alive, seen["killed"])
        print(
            f"fork pool terminated at its worker's zygote start: nothing left after {took:.3f} s (dirs {dirs}, pids {alive})"
        )
        assert not dirs and not alive
        assert took < NOTHING_WITHIN_S
    finally:
        _kill_all(pids, pid_alive)


#: An agent that registers a private dir with the dir reaper, holding the write
#: end of an inheritable pipe it then closes; it reports the reaper's pid,
#: whether a ``Popen`` of the reaper is alive in it, and its read end's fd.
QUIET_AGENT = textwrap.dedent(
    """
    import gc, json, os, subprocess, sys, tempfile
    read_end, write_end = os.pipe()
    os.set_inheritable(write_end, True)
    from remoteenv.agent.launch import dir_reaper
    path = tempfile.mkdtemp(prefix="remoteenv-quiet-")
    dir_reaper.watch_dir(path)
    pid = dir_reaper.reaper_pid()
    os.close(write_end)
    held = any(isinstance(o, subprocess.Popen) and o.pid == pid for o in gc.get_objects())
    print(json.dumps({"pid": pid, "path": path, "popen_held": held}), flush=True)
    sys.stdin.read()  # until the test has looked at the pipe
    """
)


def test_the_dir_reaper_holds_none_of_its_agents_descriptors_and_ends_it_quietly(tmp_path, agent_tmpdir, pid_alive):
    # Before: the agent held the reaper as a Popen, which warned "subprocess N is
    # still running" (ResourceWarning) at every interpreter exit, e.g. pytest's.
    tmp = agent_tmpdir
    agent = subprocess.Popen(
        [sys.executable, "-X", "dev", "-c", QUIET_AGENT],
        env=_env(tmp),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    seen: dict = {}
    try:
        assert agent.stdout is not None and agent.stdin is not None
        seen = json.loads(agent.stdout.readline())
        assert not seen["popen_held"]
        # The agent closed its write end of the inheritable pipe: once the reaper
        # has closed what it inherited, nobody writes to it (timing is the
        # behaviour here: GONE_WITHIN_S bounds a loaded machine).
        with open(f"/proc/{agent.pid}/fd/{_pipe_read_end(agent.pid)}", "rb") as pipe:
            ready = select.select([pipe], [], [], GONE_WITHIN_S)[0]
            assert ready and pipe.read() == b"", "the reaper holds the agent's inheritable pipe"
        _out, err = agent.communicate("", timeout=60)
        assert agent.returncode == 0, err[-2000:]
        assert "ResourceWarning" not in err, err[-2000:]
        took, dirs, alive = _nothing_left(tmp, [seen["pid"]], pid_alive, time.monotonic())
        assert not dirs and not alive
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        _kill_all([seen["pid"]] if seen else [], pid_alive)


def _pipe_read_end(pid: int) -> int:
    """The fd of process ``pid``'s one pipe other than its stdin/stdout/stderr."""
    for name in os.listdir(f"/proc/{pid}/fd"):
        fd = int(name)
        if fd > 2 and os.readlink(f"/proc/{pid}/fd/{name}").startswith("pipe:"):
            return fd
    raise AssertionError(f"no pipe open in process {pid}")
