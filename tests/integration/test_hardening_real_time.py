"""Issue 10, item 8: in real time only the connection that drives a world may
step or reset it; a second client is refused with a clear error and the
driver's steps are all answered."""

from __future__ import annotations

import threading

import pytest
import zmq

from remoteenv import OpenAIRemoteEnv, StateError, scene_path
from remoteenv.agent.connection.zmq_connection import ZmqConnection
from remoteenv.wire import protocol


def test_a_second_client_cannot_displace_the_drivers_steps():
    env = OpenAIRemoteEnv(scene_path("cartpole"), real_time=True, timeout=10.0, startup_timeout=120.0)
    stop = threading.Event()
    refusals: list[str] = []
    try:
        endpoint = env.launcher.sims[0].endpoint

        def interfere() -> None:
            sock = zmq.Context.instance().socket(zmq.DEALER)
            sock.setsockopt(zmq.LINGER, 0)
            sock.connect(endpoint)
            seq = 0
            while not stop.is_set():
                seq += 1
                for cmd in ("step", "reset"):
                    sock.send(protocol.pack({"seq": seq, "cmd": cmd, "action": 0}))
                    if sock.poll(2000):
                        reply = protocol.unpack(sock.recv())
                        if not reply["ok"]:
                            refusals.append(reply["error"]["kind"] + ": " + reply["error"]["message"])
            sock.close(linger=0)

        env.reset(seed=0)
        thread = threading.Thread(target=interfere, daemon=True)
        thread.start()
        answered = 0
        for _ in range(20):
            _, _, terminated, _, _ = env.step(env.action_space.sample())
            answered += 1
            if terminated:
                env.reset()
        stop.set()
        thread.join(10)
        assert answered == 20
        assert refusals and all(r.startswith("state: ") and "driven by another connection" in r for r in refusals)
        # Read-only commands stay open to everyone.
        reader = ZmqConnection(endpoint, timeout=10.0)
        try:
            assert reader.request("timing", clear=False)["worlds"]
        finally:
            reader.close()
    finally:
        stop.set()
        env.close()


def test_without_a_launching_pipe_a_driven_world_stays_its_drivers():
    # Issue 35, item 4: before, the other client's reset took the world over.
    env = OpenAIRemoteEnv(scene_path("cartpole"), transport="ipc", real_time=True, timeout=10.0, startup_timeout=120.0)
    try:
        env.reset(seed=0)
        other = ZmqConnection(env.launcher.sims[0].endpoint, timeout=10.0)
        try:
            for cmd, args in (("step", {"action": 0}), ("reset", {})):
                with pytest.raises(StateError, match="driven by another connection"):
                    other.request(cmd, **args)
        finally:
            other.close()
        env.step(env.action_space.sample())  # the driver drives on
    finally:
        env.close()


def test_a_second_client_cannot_pause_or_resume_the_drivers_clock():
    env = OpenAIRemoteEnv(scene_path("cartpole"), real_time=True, timeout=10.0, startup_timeout=120.0)
    try:
        env.reset(seed=0)
        other = ZmqConnection(env.launcher.sims[0].endpoint, timeout=10.0)
        try:
            for cmd in ("pause", "resume"):
                with pytest.raises(StateError, match="driven by another connection"):
                    other.request(cmd)
        finally:
            other.close()
        env.unwrapped.pause()  # the driver may
        assert env.unwrapped.is_paused
        env.unwrapped.resume()
        env.step(env.action_space.sample())
    finally:
        env.close()
