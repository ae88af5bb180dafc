"""Only the sim's owner, the connection that drives its worlds, may stop it,
in lock-step and in real time; nobody else may step a world someone drives.

A second client reaches the sim's ZeroMQ endpoint (ipc, same uid; or tcp on
loopback, where any local user could) while the owner drives it, over the
launching pipe or, without one, over ZeroMQ itself.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from remoteenv import OpenAIRemoteEnv, RemoteVectorEnv, StateError, scene_path
from remoteenv.agent.connection.zmq_connection import ZmqConnection
from remoteenv.agent.launch.launcher import pid_alive


def _gone(pid: int, within_s: float = 30.0) -> bool:
    deadline = time.monotonic() + within_s  # generous: a loaded 2-core machine
    while pid_alive(pid):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


@pytest.mark.parametrize("real_time", [False, True], ids=["lock_step", "real_time"])
@pytest.mark.parametrize("transport", ["pipe", "tcp"])
def test_a_second_client_can_neither_close_nor_step_the_owners_sim(transport, real_time):
    env = OpenAIRemoteEnv(
        scene_path("cartpole"), transport=transport, real_time=real_time, timeout=20.0, startup_timeout=120.0
    )
    try:
        pid = env.pid
        env.reset(seed=0)
        other = ZmqConnection(env.launcher.sims[0].endpoint, timeout=20.0)
        try:
            for cmd, args in (("close", {}), ("step", {"action": 0}), ("pause", {})):
                if cmd == "pause" and not real_time:
                    continue
                with pytest.raises(StateError, match="driven by another connection"):
                    other.request(cmd, **args)
            assert other.request("render")["ok"]  # read-only commands stay open
        finally:
            other.close()
        assert pid_alive(pid)
        for _ in range(3):
            obs, *_ = env.step(env.action_space.sample())  # the owner's sim serves on
        assert obs.shape == (4,)
    finally:
        env.close()
    assert _gone(pid)


def test_a_second_client_cannot_step_a_lock_step_vector_sim_over_zeromq():
    env = RemoteVectorEnv(scene_path("cartpole"), 2, envs_per_process=2, startup_timeout=120.0, timeout=20.0)
    try:
        env.reset(seed=0)
        other = ZmqConnection(env.launcher.sims[0].endpoint, timeout=20.0)
        try:
            for cmd, args in (
                ("step_batch", {"ops": [0, 0], "actions": np.zeros(2, np.int64)}),
                ("reset_batch", {"worlds": [0, 1], "seeds": None}),
                ("close", {}),
            ):
                with pytest.raises(StateError, match="driven by another connection"):
                    other.request(cmd, **args)
        finally:
            other.close()
        obs, *_ = env.step(np.array([0, 1]))
        assert obs.shape == (2, 4)
    finally:
        env.close()


@contextlib.contextmanager
def _launched(tmp_path, *args: str) -> Iterator[list[dict]]:
    """A ``python -m remoteenv launch cartpole`` server for the ``with`` block
    (its launch-info instances); stopped after it, its sims gone."""
    out = tmp_path / "launch.json"
    launch = subprocess.Popen(
        [sys.executable, "-m", "remoteenv", "launch", "cartpole", "--out", str(out), *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    instances: list[dict] = []
    try:
        deadline = time.monotonic() + 120
        while not out.exists():
            assert launch.poll() is None, launch.stderr.read()  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "launch wrote no launch-info file"
            time.sleep(0.05)
        instances = json.loads(out.read_text())["instances"]
        yield instances
    finally:
        if launch.poll() is None:
            launch.send_signal(signal.SIGTERM)
        launch.wait(timeout=60)
        launch.stderr.close()  # type: ignore[union-attr]
    assert all(_gone(s["pid"]) for s in instances)


def test_a_second_tcp_client_cannot_take_over_the_world_of_an_agent_attached_to_a_launched_sim(tmp_path):
    # Issue 35, item 4: a reset from another client took the driver role of a
    # real-time sim started with `launch`, locking out the attached agent. Now
    # a driven world stays its driver's until the driver's connection ends.
    out = tmp_path / "launch.json"
    with _launched(tmp_path, "--transport", "tcp", "--real-time") as instances:
        agent = OpenAIRemoteEnv.attach(out, timeout=20.0)
        try:
            agent.reset(seed=0)
            other = ZmqConnection(instances[0]["endpoint"], timeout=20.0)
            try:
                for cmd, args in (("reset", {"seed": 1}), ("step", {"action": 0}), ("close", {})):
                    with pytest.raises(StateError, match="driven by another connection"):
                        other.request(cmd, **args)
            finally:
                other.close()
            for _ in range(5):
                _, _, terminated, _, _ = agent.step(agent.action_space.sample())  # the agent still drives
                if terminated:
                    agent.reset()
        finally:
            agent.close()
        # The attached agent's connection ended: the world is free for the next one.
        late = OpenAIRemoteEnv.attach(out, timeout=20.0)
        try:
            late.reset(seed=2)
            late.step(late.action_space.sample())
        finally:
            late.close()


@pytest.mark.parametrize("kind", ["single", "vector"])
def test_an_agent_gets_the_world_its_previous_driver_lets_go_of_while_it_resets(tmp_path, kind):
    # The sim frees a world when its socket monitor reports the driver's
    # disconnect, a moment after the close: an agent whose reset comes in
    # that moment resends it (for up to DRIVER_RELEASE_GRACE_S, 2 s) instead of
    # failing. Here the previous driver still holds the world when the reset
    # is first sent and lets go 0.3 s later (well inside the grace).
    with _launched(tmp_path, "--worlds", "2") as instances:
        holder = ZmqConnection(instances[0]["endpoint"], timeout=20.0)
        letting_go = threading.Timer(0.3, holder.close)
        try:
            holder.request("reset_batch", worlds=[0, 1], seeds=None)
            other = ZmqConnection(instances[0]["endpoint"], timeout=20.0)
            try:
                with pytest.raises(StateError, match="driven by another connection"):
                    other.request("reset", world=0, seed=0)
            finally:
                other.close()
            attach = OpenAIRemoteEnv.attach if kind == "single" else RemoteVectorEnv.attach
            agent = attach(tmp_path / "launch.json", timeout=20.0)
            try:
                letting_go.start()
                obs, _ = agent.reset(seed=3)
                letting_go.join()
                agent.step(agent.action_space.sample())
                assert obs.shape == ((4,) if kind == "single" else (2, 4))
            finally:
                agent.close()
        finally:
            letting_go.cancel()
            if letting_go.ident is not None:
                letting_go.join()
            holder.close()


def test_a_world_still_driven_after_the_grace_is_refused(tmp_path):
    with _launched(tmp_path) as instances:
        holder = ZmqConnection(instances[0]["endpoint"], timeout=20.0)
        try:
            holder.request("reset", seed=0)
            agent = OpenAIRemoteEnv.attach(tmp_path / "launch.json", timeout=20.0)
            try:
                with pytest.raises(StateError, match="driven by another connection"):
                    agent.reset(seed=1)
            finally:
                agent.close()
            holder.request("step", action=0)  # the holder drives on
        finally:
            holder.close()
