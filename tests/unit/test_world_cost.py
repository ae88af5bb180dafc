"""What one world costs, measured for the default layout: the whole tick of a
scratch world (every hook, however the scene spends it), asked for in the
handshake; and when the measurement can matter at all."""

from __future__ import annotations

import time
from typing import Any

from remoteenv.agent.vector import vector_layout
from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.scene.world_cost import measured_cost, step_cost, world_cost
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.wire import protocol
from remoteenv.wire.messages.handshake import handshake_request, parse_handshake

HOOK_S = 0.004


class SlowHookCartPole(CartPoleEnv):
    """A CartPole whose post_step does a costly thing of its own (as a scene that renders in its hook)."""

    made: list[SlowHookCartPole] = []

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.resets: list[int | None] = []
        self.actions: list[Any] = []
        self.closed = False
        SlowHookCartPole.made.append(self)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        self.resets.append(seed)
        return super().reset(seed=seed, options=options)

    def post_step(self, action: Any) -> Any:
        self.actions.append(action)
        time.sleep(HOOK_S)
        return super().post_step(action)

    def close(self) -> None:
        self.closed = True
        super().close()


def test_step_cost_times_every_hook_of_a_scratch_world_and_closes_it():
    SlowHookCartPole.made.clear()
    cost = step_cost(lambda: SlowHookCartPole(continuous=True))
    (world,) = SlowHookCartPole.made
    assert cost >= HOOK_S  # the hook's own work is in the figure (a sleep lasts at least its length)
    assert world.resets[0] == 0 and world.closed
    assert len(world.actions) >= 2 and all(world.action_space.contains(a) for a in world.actions)


def test_the_estimate_of_physics_alone_misses_a_hook_the_measurement_sees():
    world = SlowHookCartPole(continuous=True)
    world.reset(seed=0)
    assert world_cost(world) < HOOK_S  # physics on a scratch MjData: the hook is not called
    assert measured_cost(world, lambda: SlowHookCartPole(continuous=True)) >= HOOK_S
    world.close()


def test_a_factory_that_fails_falls_back_to_the_estimate():
    world = CartPoleEnv()
    world.reset(seed=0)

    def broken() -> CartPoleEnv:
        raise RuntimeError("no display")

    assert 0 < measured_cost(world, broken) < 1.0
    world.close()


def test_the_handshake_measures_only_when_asked(tmp_path):
    envs = [CartPoleEnv(continuous=True) for _ in range(2)]
    made: list[int] = []

    def factory() -> CartPoleEnv:
        made.append(1)
        return CartPoleEnv(continuous=True)

    server = RemoteControlledAgent(envs, f"ipc://{tmp_path}/sim.sock", world_factory=factory)
    try:
        plain = server.handle_frame(protocol.pack({"seq": 1, "cmd": "handshake", **handshake_request()}))
        assert parse_handshake(plain).world_cost_s is None and not made
        asked = server.handle_frame(protocol.pack({"seq": 2, "cmd": "handshake", **handshake_request(world_cost=True)}))
        assert parse_handshake(asked).world_cost_s > 0 and made == [1]
        again = server.handle_frame(protocol.pack({"seq": 3, "cmd": "handshake", **handshake_request(world_cost=True)}))
        assert parse_handshake(again).world_cost_s == parse_handshake(asked).world_cost_s and made == [1]
    finally:
        server.shutdown()


def test_a_probe_is_measured_on_its_own_world_which_stays_open(tmp_path):
    SlowHookCartPole.made.clear()
    world = SlowHookCartPole(continuous=True)
    made: list[int] = []

    def factory() -> SlowHookCartPole:
        made.append(1)
        return SlowHookCartPole(continuous=True)

    server = RemoteControlledAgent([world], f"ipc://{tmp_path}/sim.sock", world_factory=factory)
    try:
        request = handshake_request(world_cost=True, probe=True)
        assert request == {"protocol": protocol.PROTOCOL_VERSION, "world_cost": True, "probe": True}
        reply = server.handle_frame(protocol.pack({"seq": 1, "cmd": "handshake", **request}))
        assert parse_handshake(reply).world_cost_s >= HOOK_S  # the hook's work, on world 0 itself
        assert not made and SlowHookCartPole.made == [world]  # no scratch world
        assert world.resets[0] == 0 and len(world.actions) >= 2 and not world.closed
    finally:
        server.shutdown()
    assert handshake_request(probe=True) == {"protocol": protocol.PROTOCOL_VERSION}  # a probe only with a measure


def test_the_cost_is_measured_only_where_it_can_change_the_layout(monkeypatch):
    monkeypatch.setattr(vector_layout.os, "cpu_count", lambda: 2)
    may = vector_layout.cost_may_change_layout
    assert [n for n in (1, 2, 3, 4, 8, 9, 15, 16, 17, 64) if may(n)] == [2, 3, 4, 8, 9, 15, 16, 17, 64]
