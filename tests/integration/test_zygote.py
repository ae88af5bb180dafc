"""Sims forked by a zygote: fresh per env, the plain start where a zygote
cannot be used, user scenes, restarts, and nothing left when the agent dies."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import time

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv import Launcher, OpenAIRemoteEnv
from remoteenv.agent.launch.sim_command import launch_environment
from remoteenv.agent.launch.zygote import registry
from remoteenv.cli.new_scene import write_package

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes")
DRAWS = os.path.join(SCENES, "draws_scene.py")
CARTPOLE = "remoteenv/CartPole-v0"


def _parent(pid: int) -> int:
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[1])


def _sim(env) -> remoteenv.agent.launch.sim_process.SimProcess:
    return env.unwrapped.launcher.sims[0]


@pytest.fixture
def zygotes_on(monkeypatch):
    monkeypatch.setenv(registry.SWITCH, "1")


def test_each_env_gets_a_fresh_sim_forked_by_one_zygote(zygotes_on, closing):
    a, b = gym.make(CARTPOLE), gym.make(CARTPOLE)
    plain = gym.make(CARTPOLE, launcher=Launcher(zygote=False))
    for env in (a, b, plain):
        closing(env)
    zygote = _sim(a).zygote_pid
    assert zygote is not None and _sim(b).zygote_pid == zygote and _sim(plain).zygote_pid is None
    assert _parent(a.unwrapped.pid) == _parent(b.unwrapped.pid) == zygote and _parent(zygote) == os.getpid()
    assert a.unwrapped.pid != b.unwrapped.pid
    # The same seed gives the same start in a forked sim and in one started the plain way.
    first = [env.reset(seed=7)[0] for env in (a, b, plain)]
    np.testing.assert_array_equal(first[0], first[1])
    np.testing.assert_array_equal(first[0], first[2])
    # Unseeded, each sim draws its own start: no RNG state came from the zygote.
    c, d = gym.make(CARTPOLE), gym.make(CARTPOLE)
    closing(c)
    closing(d)
    assert _sim(c).zygote_pid == _sim(d).zygote_pid == zygote
    assert not np.array_equal(c.reset()[0], d.reset()[0])
    # A model changed in one sim is not changed in the other.
    a.unwrapped.set_scene_attr("pole_mass", 0.5)
    assert a.unwrapped.get_scene_attr("pole_mass") == 0.5 and b.unwrapped.get_scene_attr("pole_mass") == 0.1


def test_forked_sims_draw_their_own_global_random_numbers(zygotes_on, closing):
    envs = [OpenAIRemoteEnv(DRAWS) for _ in range(2)]
    for env in envs:
        closing(env)
    assert all(env.launcher.sims[0].zygote_pid is not None for env in envs)
    draws = [env.get_scene_attr("global_draws") for env in envs]
    assert draws[0][0] != draws[1][0], "numpy's global RNG state came from the zygote"
    assert draws[0][1] != draws[1][1], "Python's random state came from the zygote"


def test_the_zygotes_imports_stay_out_of_its_sims_collections(zygotes_on, closing):
    # A collection (the one at the sim's exit too) would visit every object the
    # zygote imported, copying its pages into the sim.
    forked = OpenAIRemoteEnv(DRAWS)
    plain = OpenAIRemoteEnv(DRAWS, launcher=Launcher(zygote=False))
    for env in (forked, plain):
        closing(env)
    assert forked.launcher.sims[0].zygote_pid is not None and plain.launcher.sims[0].zygote_pid is None
    assert forked.get_scene_attr("frozen_objects") > 10_000  # numpy, mujoco, gymnasium, remoteenv's sim side
    assert plain.get_scene_attr("frozen_objects") == 0


def test_the_plain_start_when_zygotes_are_off(monkeypatch, closing):
    monkeypatch.setenv(registry.SWITCH, "0")
    env = gym.make(CARTPOLE)
    closing(env)
    env.reset(seed=0)
    assert _sim(env).zygote_pid is None and _parent(env.unwrapped.pid) == os.getpid()
    monkeypatch.setenv(registry.SWITCH, "1")
    env = gym.make(CARTPOLE, launcher=Launcher(zygote=False))
    closing(env)
    assert _sim(env).zygote_pid is None and _parent(env.unwrapped.pid) == os.getpid()


SHADOWING_SCENE = textwrap.dedent(
    """
    import farama_notifications
    from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
    from remoteenv.sim import run_scene

    class Where(CartPoleEnv):
        helper = getattr(farama_notifications, "WHERE", "site-packages")

    if __name__ == "__main__":
        run_scene(Where)
    """
)


def test_a_scene_folder_that_shadows_a_preloaded_module_gets_the_plain_start(zygotes_on, tmp_path, closing):
    # Gymnasium imports farama_notifications (and tolerates anything there), so the
    # zygote has it; a fresh interpreter imports the scene folder's file instead.
    (tmp_path / "farama_notifications.py").write_text("notifications = {}\nWHERE = 'scene folder'\n")
    (tmp_path / "where_scene.py").write_text(SHADOWING_SCENE)
    for _ in range(2):
        env = OpenAIRemoteEnv(str(tmp_path / "where_scene.py"))
        closing(env)
        assert env.get_scene_attr("helper") == "scene folder"
        assert env.launcher.sims[0].zygote_pid is None


USER_MODULE_SCENE = textwrap.dedent(
    """
    import sys
    import argv_reader
    from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
    from remoteenv.sim import run_scene

    class Seen(CartPoleEnv):
        argv_at_import = argv_reader.ARGV

    if __name__ == "__main__":
        run_scene(Seen)
    """
)


def test_a_scene_imports_its_users_modules_itself(zygotes_on, monkeypatch, tmp_path, closing):
    # argv_reader (on PYTHONPATH, not installed) reads sys.argv when imported: the
    # zygote must not import it ahead of the scene, or every sim would see the zygote's.
    lib, folder = tmp_path / "lib", tmp_path / "scene"
    lib.mkdir()
    folder.mkdir()
    (lib / "argv_reader.py").write_text("import sys\nARGV = list(sys.argv)\n")
    (folder / "seen_scene.py").write_text(USER_MODULE_SCENE)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(lib), os.environ.get("PYTHONPATH", "")]))
    for instance in range(2):
        env = OpenAIRemoteEnv(str(folder / "seen_scene.py"), seed=instance)
        closing(env)
        assert env.launcher.sims[0].zygote_pid is not None
        argv = env.get_scene_attr("argv_at_import")
        assert argv[0] == str(folder / "seen_scene.py") and argv[argv.index("--seed") + 1] == str(instance)


def test_a_user_scene_from_new_scene_is_forked(zygotes_on, tmp_path, closing):
    write_package("point_mass", tmp_path / "pkg")
    scene = tmp_path / "pkg" / "src" / "point_mass" / "point_mass_scene.py"
    env = OpenAIRemoteEnv(str(scene))
    closing(env)
    assert env.launcher.sims[0].zygote_pid is not None
    env.reset(seed=0)
    obs, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)


def _kill_group(pid: int) -> None:
    os.killpg(pid, signal.SIGKILL)


def test_a_crashed_sim_is_relaunched_by_the_same_zygote(zygotes_on, closing, wait_gone):
    env = OpenAIRemoteEnv(remoteenv.scene_path("cartpole"), restart_on_failure=True)
    closing(env)
    env.reset(seed=0)
    before = env.launcher.sims[0]
    _kill_group(before.pid)
    assert wait_gone(before.pid)
    *_, info = env.step(0)
    after = env.launcher.sims[0]
    assert info["remoteenv_restarted"] and after.pid != before.pid
    assert after.zygote_pid == before.zygote_pid is not None
    assert "killed by signal SIGKILL" in (before.death() or "")  # the zygote reported the real status


def test_a_killed_zygote_leaves_its_sims_serving_and_is_replaced(zygotes_on, closing, wait_gone):
    env = OpenAIRemoteEnv(remoteenv.scene_path("cartpole"), restart_on_failure=True)
    closing(env)
    env.reset(seed=0)
    sim = env.launcher.sims[0]
    os.kill(sim.zygote_pid, signal.SIGKILL)
    assert wait_gone(sim.zygote_pid)
    for _ in range(3):  # a sim watches its agent, not the zygote
        env.step(0)
    assert sim.death() is None
    other = gym.make(CARTPOLE)
    closing(other)
    assert _sim(other).zygote_pid not in (None, sim.zygote_pid)
    _kill_group(sim.pid)
    sim.proc.wait(10.0)
    assert "lost with its zygote" in (sim.death() or "")
    *_, info = env.step(0)
    assert info["remoteenv_restarted"] and env.launcher.sims[0].zygote_pid == _sim(other).zygote_pid


AGENT = textwrap.dedent(
    """
    import json, sys, time
    import gymnasium as gym
    import remoteenv
    env = gym.make("remoteenv/CartPole-v0")
    env.reset(seed=0)
    sim = env.unwrapped.launcher.sims[0]
    print(json.dumps([sim.pid, sim.zygote_pid, env.unwrapped.launcher.workdir]), flush=True)
    time.sleep(600)
    """
)


def test_the_zygote_and_its_sims_end_with_their_agent(zygotes_on, wait_gone):
    agent = subprocess.Popen([sys.executable, "-c", AGENT], stdout=subprocess.PIPE, text=True)
    try:
        line = agent.stdout.readline()  # type: ignore[union-attr]
        assert line, f"agent exited early with code {agent.wait()}"
        sim, zygote, workdir = json.loads(line)
        assert zygote is not None and _parent(zygote) == agent.pid
        agent.kill()
        agent.wait()
        # Timing is part of the behaviour: bounds generous for a loaded 2-core machine.
        assert wait_gone(zygote, 5.0) and wait_gone(sim, 5.0)
        deadline = time.monotonic() + 5.0
        while os.path.exists(workdir) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not os.path.exists(workdir)
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        agent.stdout.close()  # type: ignore[union-attr]


def _worker(queue) -> None:
    env = gym.make(CARTPOLE)
    env.reset(seed=0)
    zygote = env.unwrapped.launcher.sims[0].zygote_pid
    queue.put((os.getpid(), zygote, _parent(zygote)))
    env.close()


def test_a_process_forked_from_the_agent_starts_its_own_zygote(zygotes_on, closing, wait_gone):
    env = gym.make(CARTPOLE)
    closing(env)
    ours = _sim(env).zygote_pid
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    worker = ctx.Process(target=_worker, args=(queue,))
    worker.start()
    worker_pid, theirs, parent = queue.get(timeout=120)
    worker.join(60)
    assert theirs not in (None, ours) and parent == worker_pid
    assert wait_gone(theirs, 5.0), "the worker's zygote must end with the worker"
    env.reset(seed=0)  # ours is untouched
    assert _parent(ours) == os.getpid()


def test_prestart_starts_the_zygote_the_next_launch_forks_from(monkeypatch, closing):
    monkeypatch.setenv(registry.SWITCH, "0")
    assert remoteenv.prestart(CARTPOLE) is False
    monkeypatch.setenv(registry.SWITCH, "1")
    assert remoteenv.prestart(CARTPOLE, render_mode="human") is False
    assert remoteenv.prestart(CARTPOLE) is True
    zygote = registry.zygote_for(launch_environment(None))
    assert zygote is not None
    env = gym.make(CARTPOLE)
    closing(env)
    assert _sim(env).zygote_pid == zygote.pid


def test_a_zygote_that_names_another_pid_is_not_believed(zygotes_on, monkeypatch, closing, wait_gone):
    # The launcher signals a sim's process group by the pid the zygote names:
    # it must be the pid of the pidfd that came with it, or the sim starts the plain way.
    liar = os.path.join(os.path.dirname(os.path.abspath(__file__)), "servers", "lying_zygote.py")
    monkeypatch.setattr("remoteenv.agent.launch.zygote.process.START_SCRIPT", liar)
    monkeypatch.setenv("REMOTEENV_TEST_LYING_ZYGOTE", "1")  # a key of its own: no real zygote is reused
    zygote = registry.zygote_for(launch_environment(None))
    assert zygote is not None
    env = gym.make(CARTPOLE)
    closing(env)
    env.reset(seed=0)
    assert _sim(env).zygote_pid is None and _parent(env.unwrapped.pid) == os.getpid()
    assert not zygote.alive and wait_gone(zygote.pid)
