"""The driver rule, in-process: one connection drives each world in both
stepping modes; only it may reset or step the world, and only the connection
driving the worlds (the sim's owner: its launching pipe, else the first to
reset them, until its connection ends) may close the sim. Connections are ``(channel, routing id)`` pairs
passed to ``handle`` directly; no request crosses a socket.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.sim.transport.drivers import Drivers
from remoteenv.wire.run_options.options import RunOptions


class FakeClock:
    def __call__(self) -> float:
        return 0.0


@pytest.fixture
def make(tmp_path) -> Iterator[Any]:
    made: list[tuple[RemoteControlledAgent, socket.socket | None]] = []

    def make_server(mode: str, worlds: int = 2, pipe: bool = False) -> RemoteControlledAgent:
        agent_end = sim_end = None
        if pipe:
            agent_end, sim_end = socket.socketpair()
        kwargs: dict[str, Any] = (
            {"run": RunOptions(real_time=True), "clock": FakeClock()} if mode == "real_time" else {}
        )
        server = RemoteControlledAgent(
            [CartPoleEnv() for _ in range(worlds)],
            f"ipc://{tmp_path}/sim-{len(made)}.sock",
            pipe_fd=None if sim_end is None else sim_end.detach(),
            **kwargs,
        )
        made.append((server, agent_end))
        return server

    yield make_server
    for server, agent_end in made:
        server.shutdown()
        if agent_end is not None:
            agent_end.close()


def call(server: RemoteControlledAgent, who: tuple[Any, Any], cmd: str, **fields: Any) -> dict[str, Any] | None:
    return server.handle({"seq": 3, "cmd": cmd, **fields}, who[0], who[1])


def refused(reply: dict[str, Any] | None) -> bool:
    if reply is None or reply["ok"]:
        return False
    err = reply["error"]
    assert err["kind"] == "state" and "driven by another connection" in err["message"], err
    return True


def zmq_peers(server: RemoteControlledAgent) -> tuple[tuple[Any, bytes], tuple[Any, bytes]]:
    router = server.channels[0]
    return (router, b"\x00owner"), (router, b"\x00other")


@pytest.mark.parametrize("mode", ["lock_step", "real_time"])
def test_without_a_pipe_only_the_driving_connection_may_step_or_close(make, mode):
    server = make(mode)
    owner, other = zmq_peers(server)
    for world in (0, 1):
        assert call(server, owner, "reset", world=world, seed=0)["ok"]
    assert not refused(call(server, owner, "step", world=0, action=1))
    assert refused(call(server, other, "step", world=0, action=1))
    assert refused(call(server, other, "close"))
    assert server.running  # the refused close stopped nothing
    assert call(server, other, "handshake", protocol=1)["ok"]  # open to all
    assert call(server, other, "render")["ok"]
    assert call(server, owner, "close")["ok"] and not server.running


@pytest.mark.parametrize("mode", ["lock_step", "real_time"])
def test_with_a_pipe_no_zeromq_client_may_reset_step_or_close(make, mode):
    server = make(mode, pipe=True)
    pipe = (server.channels[1], None)
    _, other = zmq_peers(server)
    assert call(server, pipe, "reset", world=0, seed=0)["ok"]
    assert refused(call(server, other, "reset", world=0, seed=0))
    assert refused(call(server, other, "reset", world=1, seed=0))  # never reset: the pipe drives it all the same
    assert refused(call(server, other, "step", world=0, action=1))
    assert refused(call(server, other, "close"))
    assert server.running
    assert call(server, pipe, "close")["ok"] and not server.running


def test_a_driven_world_stays_its_drivers_and_the_owner_must_drive_every_world(make):
    # Issue 35, item 4: a reset no longer takes a world over (it did: a second
    # tcp client locked the agent attached to a launched sim out of its world).
    server = make("lock_step")
    a, b = zmq_peers(server)
    assert call(server, a, "reset", world=0, seed=0)["ok"]
    assert call(server, b, "reset", world=1, seed=0)["ok"]
    assert refused(call(server, a, "close")) and refused(call(server, b, "close"))  # each drives one world
    assert refused(call(server, a, "step", world=1, action=1))
    assert refused(call(server, a, "reset", world=1, seed=0))  # b's world stays b's
    assert call(server, b, "step", world=1, action=1)["ok"]
    server.drivers.release(b)  # b's connection ends (the socket monitor's notice; see test_hardening_owner)
    assert server.drivers.driver(1) is None
    assert call(server, a, "reset", world=1, seed=0)["ok"]  # now a may take it
    assert refused(call(server, b, "step", world=1, action=1))
    assert call(server, a, "step", world=1, action=1)["ok"]
    assert call(server, a, "close")["ok"] and not server.running


@pytest.mark.parametrize("mode", ["lock_step", "real_time"])
def test_a_step_on_a_world_nobody_drives_makes_its_sender_the_driver(make, mode):
    # After a disconnect notice that came between an agent's timeout and its
    # reconnect (same routing id), its next step takes its worlds back.
    server = make(mode, worlds=1)
    a, b = zmq_peers(server)
    assert call(server, a, "reset", world=0, seed=0)["ok"]
    server.drivers.release(a)
    call(server, a, "step", world=0, action=1)  # real time answers later (None now)
    assert server.drivers.driver(0) == a
    assert refused(call(server, b, "reset", world=0, seed=0))


def test_the_launching_pipe_is_never_released(make):
    server = make("lock_step", pipe=True)
    pipe = (server.channels[1], None)
    server.drivers.release(pipe)
    assert server.drivers.driver(0) == pipe


def test_batches_follow_the_driver_rule(make):
    server = make("lock_step", worlds=3)
    a, b = zmq_peers(server)
    assert call(server, a, "reset_batch", worlds=[0, 1], seeds=None)["ok"]
    assert call(server, b, "reset_batch", worlds=[2], seeds=None)["ok"]
    actions = np.zeros(2, np.int64)
    assert call(server, a, "step_batch", ops=[0, 0], actions=actions)["ok"]  # worlds 0, 1
    assert refused(call(server, b, "step_batch", ops=[0, 0], actions=actions))
    assert refused(call(server, a, "step_batch", ops=[0, 0], actions=actions, worlds=[1, 2]))
    assert call(server, b, "step_batch", ops=[0], actions=actions[:1], worlds=[2])["ok"]
    # Ill-formed requests get the handler's own protocol error, not a state error.
    reply = call(server, b, "step_batch", ops="x", actions=actions)
    assert reply is not None and reply["error"]["kind"] == "protocol"
    reply = call(server, b, "reset_batch", worlds=[7], seeds=None)
    assert reply is not None and reply["error"]["kind"] == "protocol"


def test_with_a_pipe_zeromq_batches_are_refused(make):
    server = make("lock_step", pipe=True)
    pipe = (server.channels[1], None)
    _, other = zmq_peers(server)
    assert call(server, pipe, "reset_batch", worlds=[0, 1], seeds=None)["ok"]
    assert refused(call(server, other, "reset_batch", worlds=[0], seeds=None))
    assert refused(call(server, other, "step_batch", ops=[0], actions=np.zeros(1, np.int64)))
    assert call(server, pipe, "step_batch", ops=[0, 0], actions=np.zeros(2, np.int64))["ok"]


def test_nobody_drives_a_fresh_world_and_the_routing_ids_of_drivers_are_known():
    drivers = Drivers(2, 0)
    assert drivers.driver(0) is None and drivers.routing_ids == frozenset()
    drivers.require_every(("zmq", b"x"), "close")  # nothing driven: nothing to refuse
    drivers.take([0], ("zmq", b"a"), "reset")
    drivers.take([1], ("zmq", b"b"), "reset")
    assert drivers.routing_ids == {b"a", b"b"}
    drivers.release(("zmq", b"b"))
    drivers.take([1], ("zmq", b"a"), "reset")
    assert drivers.routing_ids == {b"a"}
    piped = Drivers(2, 0, launcher_channel="pipe")
    assert piped.driver(1) == ("pipe", None) and piped.routing_ids == frozenset()
