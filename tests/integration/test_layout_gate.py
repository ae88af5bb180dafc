"""The layout gate: a first launch's sim measures a scratch world and builds
the worlds it serves only once its launcher says go; turned down, it ends
before building any. A vector env of a scene that says it steps its worlds as
one batch starts through it: cheap worlds in one launch, costly ones placed
from what the gate measured."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest

from remoteenv import Launcher
from remoteenv.agent.launch.layout_gate import LayoutRejected
from remoteenv.agent.launch.processes import pid_alive
from remoteenv.agent.launch.sim_group import LaunchSpec
from remoteenv.agent.vector import layout_memory
from remoteenv.agent.vector.vector_layout import COSTLY_WORLD_S, cost_may_change_layout, default_envs_per_process
from remoteenv.sim.stepping.batch_worlds import available
from remoteenv.wire.protocol import PROTOCOL_VERSION

COUNTING = os.path.join(os.path.dirname(__file__), "scenes", "counting_scene.py")


def built(path) -> list[str]:
    return path.read_text().splitlines() if path.exists() else []


def test_a_gated_sim_builds_its_worlds_only_after_the_go(tmp_path):
    count = tmp_path / "worlds"
    launcher = Launcher(transport="pipe")
    at_gate: list[list[str]] = []

    def gate(facts) -> bool:
        time.sleep(0.3)  # longer than the sim's looks at its agent while it waits: it must keep waiting
        at_gate.append(built(count))
        assert facts.stacked_hooks is True and facts.cost_s is not None and facts.fit >= 3
        return True

    launcher.layout_gate = gate
    try:
        launcher.start(LaunchSpec(COUNTING, 1, 3, env_kwargs={"count_file": str(count)}, render_mode="rgb_array"))
        assert at_gate == [["None"]]  # the scratch world alone, made without a render mode
        assert built(count) == ["None"] + ["rgb_array"] * 3  # the served worlds, after the go
        assert launcher.layout_gate is None  # asked once
    finally:
        launcher.close()


def test_a_sim_started_the_plain_way_passes_the_gate(tmp_path):
    """Without the zygote the sim has threads before it waits (its BLAS's):
    the go must reach the wait whichever thread takes it."""
    count = tmp_path / "worlds"
    launcher = Launcher(transport="pipe", zygote=False)
    launcher.layout_gate = lambda facts: True
    try:
        launcher.start(LaunchSpec(COUNTING, 1, 2, env_kwargs={"count_file": str(count)}, startup_timeout=60.0))
        assert launcher.sims[0].zygote_pid is None
        assert built(count) == ["None"] * 3
        conn = launcher.connect(0, timeout=30.0)
        try:
            assert conn.request("handshake", protocol=PROTOCOL_VERSION)["num_worlds"] == 2
        finally:
            conn.close()
    finally:
        launcher.close()


def test_a_launch_the_gate_turns_down_ends_before_building_a_world(tmp_path):
    count = tmp_path / "worlds"
    launcher = Launcher(transport="pipe")
    launcher.layout_gate = lambda facts: False
    with pytest.raises(LayoutRejected) as info:
        launcher.start(LaunchSpec(COUNTING, 1, 4, env_kwargs={"count_file": str(count)}))
    assert info.value.facts.stacked_hooks is True
    pid = launcher.sims[0].pid if launcher.sims else None
    workdir = launcher._state.workdir if launcher._state is not None else None
    assert launcher.closed
    assert pid is None or not pid_alive(pid)
    assert workdir is None or not os.path.exists(workdir)
    assert built(count) == ["None"]  # the scratch world only


def test_a_restart_is_not_gated(tmp_path):
    count = tmp_path / "worlds"
    launcher = Launcher(transport="pipe")
    launcher.layout_gate = lambda facts: True
    try:
        launcher.start(LaunchSpec(COUNTING, 1, 2, env_kwargs={"count_file": str(count)}, startup_timeout=20.0))
        first = launcher.sims[0].pid
        os.kill(first, signal.SIGKILL)
        launcher.restart(0)  # a gated restart would wait at the gate until startup_timeout and fail
        assert launcher.sims[0].pid != first
        assert built(count) == ["None", "None", "None", "None", "None"]  # scratch + 2, then 2 more, no scratch
    finally:
        launcher.close()


@pytest.mark.skipif(not cost_may_change_layout(16), reason="one CPU: the cost changes no layout, nothing measured")
def test_cheap_worlds_start_once_through_the_gate(opened_sessions):
    env = gym.make_vec("remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point").unwrapped
    try:
        opened = [(o.processes, o.worlds_each, o.measured, o.gated) for o in opened_sessions]
        k = env.envs_per_process
        assert k == default_envs_per_process(16, env.world_cost_s) == 16
        assert opened == [(1, 16, False, True)]  # one launch, gated, never a probe or a relaunch
        assert not any(o.probe for o in opened_sessions)
        assert env.world_cost_s is not None and env.world_cost_s <= COSTLY_WORLD_S
        assert len(env.pids) == 1
        env.reset(seed=0)
        env.step(np.zeros((16, 2), np.float32))
    finally:
        env.close()


@pytest.mark.skipif(not cost_may_change_layout(8), reason="one CPU: the cost changes no layout, nothing measured")
def test_costly_worlds_are_turned_down_at_the_gate_and_placed_from_what_it_measured(opened_sessions):
    env = gym.make_vec(
        "remoteenv/CartPole-v0",
        num_envs=8,
        vectorization_mode="vector_entry_point",
        obs_mode="pixels",
        image_size=16,
    ).unwrapped
    try:
        opened = [(o.processes, o.worlds_each, o.measured, o.gated) for o in opened_sessions]
        k = env.envs_per_process
        assert env.world_cost_s is not None and env.world_cost_s > COSTLY_WORLD_S  # the cameras' rendering
        assert k == default_envs_per_process(8, env.world_cost_s) < 8
        assert opened == [(1, 8, False, True), (len(env.slices), k, False, False)]
        obs, _ = env.reset(seed=0)
        assert obs.shape == (8, 16, 16, 3)
    finally:
        env.close()


def test_worlds_started_through_the_gate_draw_their_own_unseeded_starts():
    """The gate measures a scratch world, never a served one: an unseeded
    world 0 starts where chance puts it, in every vector env."""
    firsts = []
    for _ in range(2):
        layout_memory.forget_all()  # each goes through the gate
        env = gym.make_vec("remoteenv/Reacher-v0", num_envs=16, vectorization_mode="vector_entry_point")
        try:
            obs, _ = env.reset()
            firsts.append(obs[0].copy())
        finally:
            env.close()
    layout_memory.forget_all()
    assert not np.array_equal(firsts[0], firsts[1])


WAITER = r"""
import sys
from remoteenv.benchmarks.harness.step_profile import reacher_class
import numpy  # its BLAS threads exist before the go is caught, as in a sim started the plain way
from remoteenv.sim.process.layout_gate import GoSignal, report_and_wait
go = GoSignal()
report_and_wait(sys.argv[1], reacher_class(), int(sys.argv[2]), go)
print("went on", flush=True)
"""


def _waiter(path, parent_pid):
    return subprocess.Popen(
        [sys.executable, "-c", WAITER, str(path), str(parent_pid)], stdout=subprocess.PIPE, text=True
    )


def _written(path, proc, limit_s=60.0):
    deadline = time.monotonic() + limit_s  # generous: a cold interpreter imports MuJoCo first
    while not path.exists():
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)
    return json.loads(path.read_text())


def test_the_sim_waits_at_the_gate_until_the_go(tmp_path):
    path = tmp_path / "gate.json"
    proc = _waiter(path, os.getpid())
    try:
        facts = _written(path, proc)
        assert facts["pid"] == proc.pid and facts["stacked_hooks"] is available()
        time.sleep(0.3)
        assert proc.poll() is None  # still waiting: nothing said
        os.kill(proc.pid, signal.SIGUSR1)
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0 and out.strip() == "went on"
    finally:
        proc.kill()
        proc.wait()


def test_the_sim_at_the_gate_ends_when_its_agent_is_gone(tmp_path):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # a pid that no longer runs, as the agent's would be
    path = tmp_path / "gate.json"
    proc = _waiter(path, gone.pid)
    try:
        _written(path, proc)
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0 and "went on" not in out
    finally:
        proc.kill()
        proc.wait()


EARLY_GO = r"""
import os, signal
import numpy  # a BLAS thread that does not hold the signal, as in a sim started the plain way
from remoteenv.sim.process.layout_gate import GoSignal
go = GoSignal()
os.kill(os.getpid(), signal.SIGUSR1)  # the go before the wait, taken by whichever thread
go.wait(None)
print("went on", signal.getsignal(signal.SIGUSR1) == signal.SIG_DFL, flush=True)
"""


def test_a_go_that_comes_before_the_wait_is_kept_by_any_thread():
    out = subprocess.run([sys.executable, "-c", EARLY_GO], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-400:]
    assert out.stdout.split() == ["went", "on", "True"]  # and the signal's default is back
