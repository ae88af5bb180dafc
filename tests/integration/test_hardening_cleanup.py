"""Issue 35, items 1-3: cleanup acts only on what remoteenv made, never blocks,
and never blocks the agent.

1. An agent's private dir replaced by a symlink (to a victim's dir holding
   ``sim-0.keep`` and ``sim-0.log``) before the agent dies: the sim's orphan
   cleanup (its guard, its watch, its server) and the dir reaper leave the
   victim's files alone.
2. A FIFO planted at a registered path: the dir reaper still ends, and
   ``env.close()`` returns (CPython 3.11's ``shutil.rmtree`` opened it blocking).
3. A SIGSTOPped dir reaper: the agent goes on registering and forgetting dirs
   (it blocked after 416 records), warns once, and once the reaper reads
   again it still removes the dirs registered when the agent dies.

Every agent runs with ``TMPDIR`` in the test's own dir. Timing is part of
the behaviour (processes must end, calls must return): the bounds
(``WITHIN_S``) are generous for a loaded 2-core machine; the figures are printed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

WITHIN_S = 10.0


def _env(tmp: Path) -> dict[str, str]:
    return {**os.environ, "TMPDIR": str(tmp), "MUJOCO_GL": "egl"}


def _run(script: str, tmp: Path, **kwargs) -> subprocess.Popen:
    """``python -c script`` in ``tmp`` (so it imports the installed remoteenv, not a checkout's)."""
    return subprocess.Popen([sys.executable, "-c", script], cwd=tmp, env=_env(tmp), text=True, **kwargs)


def _wait(predicate, within_s: float = WITHIN_S) -> float | None:
    """Seconds until ``predicate()`` holds (polled), None if it did not within ``within_s``."""
    start = time.monotonic()
    while not predicate():
        if time.monotonic() - start > within_s:
            return None
        time.sleep(0.02)
    return time.monotonic() - start


def _kill(pids: list[int], pid_alive) -> None:
    for pid in pids:
        if pid_alive(pid):
            os.kill(pid, signal.SIGCONT)
            os.kill(pid, signal.SIGKILL)


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim"
    victim.mkdir()
    for name in ("sim-0.keep", "sim-0.log", "sim-1.log", "notes.txt"):
        (victim / name).write_text("the victim's own file\n")
    return victim


#: An agent with one sim (pipe); it prints the sim's pid, its private dir and
#: its dir reaper's pid, then waits to be killed.
AGENT = textwrap.dedent(
    """
    import json, sys, time
    from remoteenv import OpenAIRemoteEnv, scene_path
    from remoteenv.agent.launch import dir_reaper
    env = OpenAIRemoteEnv(scene_path("cartpole"), startup_timeout=120.0)
    env.reset(seed=0)
    print(json.dumps([env.pid, env.launcher.workdir, dir_reaper.reaper_pid()]), flush=True)
    time.sleep(600)
    """
)


def test_a_private_dir_replaced_by_a_symlink_leaves_the_targets_files_alone(tmp_path, agent_tmpdir, pid_alive):
    tmp = agent_tmpdir
    victim = _victim(tmp_path)
    before = sorted(os.listdir(victim))
    agent = _run(AGENT, tmp, stdout=subprocess.PIPE)
    pids: list[int] = []
    try:
        line = agent.stdout.readline()  # type: ignore[union-attr]
        assert line, f"the agent exited early ({agent.wait()})"
        sim, workdir, reaper = json.loads(line)
        pids = [sim, reaper]
        # The registered workdir becomes a symlink to the victim's dir.
        os.rename(workdir, workdir + ".moved")
        os.symlink(victim, workdir)
        agent.kill()
        agent.wait()
        took = _wait(lambda: not pid_alive(sim) and not pid_alive(reaper))
        print(f"agent killed: its sim and reaper gone after {took} s; the victim holds {sorted(os.listdir(victim))}")
        assert took is not None
        assert sorted(os.listdir(victim)) == before
        assert os.path.islink(workdir)  # refused, not followed: the symlink is not ours to remove either
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        agent.stdout.close()  # type: ignore[union-attr]
        _kill(pids, pid_alive)


#: Registers a private dir with the dir reaper, replaces it by a FIFO (as another
#: uid could in a sticky TMPDIR between a removal and forget_dir) and exits.
FIFO_AGENT = textwrap.dedent(
    """
    import json, os, tempfile
    from remoteenv.agent.launch import dir_reaper
    path = tempfile.mkdtemp(prefix="remoteenv-")
    dir_reaper.watch_dir(path)
    os.rmdir(path)
    os.mkfifo(path)
    print(json.dumps([dir_reaper.reaper_pid(), path]), flush=True)
    """
)


def test_a_fifo_at_a_registered_path_does_not_hang_the_dir_reaper(tmp_path, agent_tmpdir, pid_alive):
    tmp = agent_tmpdir
    done = subprocess.run(
        [sys.executable, "-c", FIFO_AGENT], cwd=tmp, capture_output=True, text=True, timeout=120, env=_env(tmp)
    )
    reaper, path = json.loads(done.stdout)
    try:
        took = _wait(lambda: not pid_alive(reaper))
        print(f"FIFO at the registered path: the reaper ended {took} s after its agent")
        assert took is not None, "the dir reaper hangs on the FIFO"
        assert os.path.exists(path)  # not a dir it made: left alone
    finally:
        _kill([reaper], pid_alive)


#: Makes an env, replaces its private dir by a FIFO, closes the env.
FIFO_CLOSE_AGENT = textwrap.dedent(
    """
    import json, os, sys, time
    from remoteenv import OpenAIRemoteEnv, scene_path
    env = OpenAIRemoteEnv(scene_path("cartpole"), startup_timeout=120.0)
    env.reset(seed=0)
    workdir = env.launcher.workdir
    os.rename(workdir, workdir + ".moved")
    os.mkfifo(workdir)
    start = time.monotonic()
    env.close()
    print(json.dumps([time.monotonic() - start, workdir]), flush=True)
    """
)


def test_a_fifo_at_the_private_dirs_path_does_not_hang_env_close(tmp_path, agent_tmpdir):
    tmp = agent_tmpdir
    agent = _run(FIFO_CLOSE_AGENT, tmp, stdout=subprocess.PIPE)
    try:
        out, _ = agent.communicate(timeout=90)
    except subprocess.TimeoutExpired:
        agent.kill()
        agent.communicate()
        raise AssertionError("env.close() hangs on a FIFO at its private dir's path") from None
    took, workdir = json.loads(out)
    print(f"FIFO at the private dir's path: env.close() returned in {took:.2f} s")
    assert agent.returncode == 0
    assert took < WITHIN_S
    assert Path(workdir).is_fifo()  # not the dir it made: left alone


#: Registers a dir (starting the reaper), waits for the test to SIGSTOP the
#: reaper, then registers and forgets 5000 dirs; reports how many warnings it
#: got; registers one more dir once the test has resumed the reaper; waits to be killed.
STOPPED_REAPER_AGENT = textwrap.dedent(
    """
    import json, os, sys, tempfile, time, warnings
    from remoteenv.agent.launch import dir_reaper
    first = tempfile.mkdtemp(prefix="remoteenv-first-")
    dir_reaper.watch_dir(first)
    print(json.dumps({"reaper": dir_reaper.reaper_pid()}), flush=True)
    sys.stdin.readline()  # the reaper is stopped now
    start = time.monotonic()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for i in range(5000):
            path = tempfile.mkdtemp(prefix="remoteenv-churn-")
            dir_reaper.watch_dir(path)
            os.rmdir(path)
            dir_reaper.forget_dir(path)
    took = time.monotonic() - start
    print(json.dumps({"took": took, "warnings": [str(w.message) for w in caught]}), flush=True)
    sys.stdin.readline()  # the reaper reads again
    last = tempfile.mkdtemp(prefix="remoteenv-last-")
    dir_reaper.watch_dir(last)
    deadline = time.monotonic() + 30
    while dir_reaper._backlog and time.monotonic() < deadline:  # written as the reaper reads again
        time.sleep(0.01)
    print(json.dumps({"registered": [first, last]}), flush=True)
    time.sleep(600)
    """
)


def test_a_stopped_dir_reaper_never_blocks_its_agent(tmp_path, agent_tmpdir, pid_alive):
    tmp = agent_tmpdir
    agent = _run(STOPPED_REAPER_AGENT, tmp, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    reaper = None
    try:
        assert agent.stdout is not None and agent.stdin is not None
        reaper = json.loads(agent.stdout.readline())["reaper"]
        os.kill(reaper, signal.SIGSTOP)
        agent.stdin.write("\n")
        agent.stdin.flush()
        ready = _wait(lambda: _has_line(agent), 60.0)
        assert ready is not None, "the agent blocks on its stopped reaper"
        churn = json.loads(agent.stdout.readline())
        print(f"5000 registrations with the reaper stopped: {churn['took']:.2f} s, warnings {churn['warnings']}")
        assert len(churn["warnings"]) == 1 and "dir reaper" in churn["warnings"][0]
        os.kill(reaper, signal.SIGCONT)
        agent.stdin.write("\n")
        agent.stdin.flush()
        registered = json.loads(agent.stdout.readline())["registered"]
        assert all(os.path.isdir(p) for p in registered)
        agent.kill()
        agent.wait()
        took = _wait(lambda: not pid_alive(reaper) and not any(os.path.exists(p) for p in registered))
        print(f"agent killed after the reaper resumed: its dirs gone after {took} s, left {os.listdir(tmp)}")
        assert took is not None
        assert os.listdir(tmp) == []
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        if reaper is not None:
            _kill([reaper], pid_alive)


def _has_line(proc: subprocess.Popen) -> bool:
    import select

    return bool(select.select([proc.stdout], [], [], 0)[0])
