"""The sim server's command table, called in-process: every refusal is a typed
error reply with the request's ``seq``, and the server keeps serving.

The worlds are real CartPole scenes built in this process; the server binds an
ipc socket in the test's temp dir but no request goes through it here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.wire import protocol
from remoteenv.wire.codec.spaces import space_from_wire
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.wire_errors import MAX_ECHO_CHARS

MakeServer = Callable[..., RemoteControlledAgent]


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def make_server(tmp_path) -> Iterator[MakeServer]:
    servers: list[RemoteControlledAgent] = []

    def make(
        worlds: int = 1, env_cls: type = CartPoleEnv, env_kwargs: dict | None = None, **kwargs: Any
    ) -> RemoteControlledAgent:
        envs = [env_cls(**(env_kwargs or {})) for _ in range(worlds)]
        server = RemoteControlledAgent(envs, f"ipc://{tmp_path}/sim-{len(servers)}.sock", **kwargs)
        servers.append(server)
        return server

    yield make
    for server in servers:
        server.shutdown()


def ask(server: RemoteControlledAgent, cmd: str, seq: int = 11, **fields: Any) -> Any:
    """Send one request through the codec, as the wire would."""
    return server.handle_frame(protocol.pack({"seq": seq, "cmd": cmd, **fields}))


def error_of(reply: dict[str, Any] | None, seq: int = 11) -> dict[str, Any]:
    assert reply is not None and reply["ok"] is False and reply["seq"] == seq, reply
    return reply["error"]


@pytest.fixture(params=["lock_step", "real_time"])
def server(request, make_server) -> RemoteControlledAgent:
    """A two-world continuous CartPole server in either stepping mode (real time on a fake clock)."""
    if request.param == "real_time":
        return make_server(2, env_kwargs={"continuous": True}, run=RunOptions(real_time=True), clock=FakeClock())
    return make_server(2, env_kwargs={"continuous": True})


# ---------------------------------------------------------------- the table


def test_handshake_describes_the_worlds_and_the_stepping(server):
    reply = ask(server, "handshake", protocol=protocol.PROTOCOL_VERSION)
    assert reply is not None and reply["ok"] and reply["seq"] == 11
    assert reply["num_worlds"] == 2 and reply["env_id"] == "remoteenv/CartPole-v0"
    assert reply["stepping"]["mode"] == ("real_time" if server.real_time else "lock_step")
    assert reply["metadata"]["frame_skip"] == 10 and reply["metadata"]["dt"] == pytest.approx(0.02)
    assert space_from_wire(reply["action_space"]) == server.envs[0].action_space


def test_each_mode_answers_its_own_commands(server):
    common = {"close", "handshake", "render", "reset", "step", "get_attr", "set_attr", "call"}
    extra = {"timing", "pause", "resume"} if server.real_time else {"reset_batch", "step_batch", "shared_batch"}
    assert set(server.commands) == common | extra


def test_protocol_version_mismatch_names_both_versions(server):
    err = error_of(ask(server, "handshake", protocol=41))
    assert err["kind"] == "protocol"
    assert "agent speaks 41" in err["message"] and f"speaks {protocol.PROTOCOL_VERSION}" in err["message"]
    err = error_of(ask(server, "handshake", protocol="v" * 100_000))
    assert len(err["message"]) < 2 * MAX_ECHO_CHARS


@pytest.mark.parametrize("cmd", ["reset", "step", "render"])
@pytest.mark.parametrize("world", [2, -1, True, "0", 1.5, None, "w" * 100_000])
def test_a_world_out_of_range_is_a_protocol_error(server, cmd, world):
    err = error_of(ask(server, cmd, world=world, action=np.zeros(1, np.float32)))
    assert err["kind"] == "protocol" and "out of range" in err["message"] and "hosts 2" in err["message"]
    assert len(err["message"]) < 2 * MAX_ECHO_CHARS


def test_step_before_reset_is_a_state_error_naming_world_and_instance(make_server):
    for server in (
        make_server(2, instance=3),
        make_server(2, instance=3, run=RunOptions(real_time=True), clock=FakeClock()),
    ):
        assert ask(server, "reset", world=0, seed=0)["ok"]
        err = error_of(ask(server, "step", world=1, action=0))
        assert err["kind"] == "state" and "world 1" in err["message"] and "instance 3" in err["message"]


@pytest.mark.parametrize(
    "fields",
    [
        {"seed": -4},
        {"seed": "abc"},
        {"seed": True},
        {"seed": 1.0},
        {"options": [1, 2]},
        {"options": "x"},
    ],
)
def test_bad_seed_or_options_are_protocol_errors(server, fields):
    err = error_of(ask(server, "reset", **fields))
    assert err["kind"] == "protocol"
    assert ask(server, "reset", seed=1)["ok"]  # still serving


@pytest.mark.parametrize(
    "action",
    [
        np.array([1.5], np.float32),
        np.array([np.nan], np.float32),
        np.zeros(2, np.float32),
        "left",
        None,
        {"a": 1},
    ],
)
def test_an_action_outside_the_space_is_an_invalid_action_error(server, action):
    assert ask(server, "reset", seed=0)["ok"]
    err = error_of(ask(server, "step", action=action))
    assert err["kind"] == "invalid_action" and "Box" in err["message"]


def test_an_unknown_command_is_a_protocol_error_listing_the_known_ones(server):
    err = error_of(ask(server, "fly"))
    assert err["kind"] == "protocol" and "'fly'" in err["message"] and "handshake" in err["message"]
    err = error_of(ask(server, "x" * 100_000))
    assert len(err["message"]) < 3 * MAX_ECHO_CHARS


@pytest.mark.parametrize(
    "frame",
    [
        b"\xc1",
        protocol.pack([1, "reset"]),
        protocol.pack({"cmd": "reset"}),
        protocol.pack({"seq": "1", "cmd": "x"}),
        protocol.pack({"seq": 1, "cmd": 5}),
    ],
)
def test_a_frame_that_is_not_a_request_gets_a_protocol_error_with_seq_minus_one(server, frame):
    err = error_of(server.handle_frame(frame), seq=-1)
    assert err["kind"] == "protocol"


def test_a_scene_exception_is_a_scene_error_with_its_traceback_and_serving_goes_on(server):
    err = error_of(ask(server, "reset", options={"low": "x"}))
    assert err["kind"] == "scene" and "ValueError" in err["message"] and "Traceback" in err["traceback"]
    assert ask(server, "reset", seed=0)["ok"]


class UnsendableInfoCartPole(CartPoleEnv):
    def reset_model(self, options: dict[str, Any] | None) -> tuple[np.ndarray, dict[str, Any]]:
        obs, _ = super().reset_model(options)
        return obs, {"handle": object()}


def test_a_reply_that_cannot_be_encoded_becomes_a_typed_scene_error(make_server):
    server = make_server(env_cls=UnsendableInfoCartPole)
    reply = ask(server, "reset", seq=5, seed=0)
    assert reply is not None and reply["ok"]  # computed fine; the wire refuses it
    sent = protocol.unpack(server.pack_reply(reply))
    assert sent["seq"] == 5 and sent["ok"] is False
    assert sent["error"]["kind"] == "scene" and "cannot be sent on the wire" in sent["error"]["message"]


def test_close_answers_then_stops_serving(server):
    assert server.running
    reply = ask(server, "close")
    assert reply == {"seq": 11, "ok": True}
    assert not server.running


def test_render_returns_a_frame_or_nil(make_server):
    assert ask(make_server(), "render")["frame"] is None  # no render mode
    frame = ask(make_server(env_kwargs={"render_mode": "rgb_array", "width": 32, "height": 24}), "render")["frame"]
    assert frame.shape == (24, 32, 3) and frame.dtype == np.uint8


# ---------------------------------------------------------------- stepping


def test_a_lock_step_step_is_answered_at_once(make_server):
    server = make_server()
    obs = ask(server, "reset", seed=0)["obs"]
    reply = ask(server, "step", seq=12, action=1)
    assert reply["seq"] == 12 and reply["ok"] and reply["reward"] == 1.0
    assert reply["obs"].shape == obs.shape and not np.array_equal(reply["obs"], obs)


def test_a_real_time_step_is_answered_by_its_world_when_its_tick_ends(make_server):
    clock = FakeClock()
    server = make_server(env_kwargs={"continuous": True}, run=RunOptions(real_time=True), clock=clock)
    stepping = server.stepping
    assert ask(server, "reset", seed=0)["ok"]
    assert stepping.clock_waiting  # the loop starts the clock once the reply is sent
    stepping.start_clocks(clock())
    assert ask(server, "step", seq=21, action=np.array([0.5], np.float32)) is None
    replies: list[Any] = []
    while not replies:
        clock.t = stepping.next_deadline()
        replies = list(stepping.run_due(clock.t))
    ((channel, _, reply),) = replies
    assert channel is None  # handed in directly, so the reply has nowhere to go
    assert reply["seq"] == 21 and reply["ok"] and reply["info"]["action_sim_time"] is not None
    substeps = stepping.worlds[0].substeps
    timing = ask(server, "timing", clear=True)
    assert timing["ok"] and timing["worlds"][0]["substeps"] == substeps > 0
    assert ask(server, "timing")["worlds"][0]["substeps"] == 0


def test_real_time_and_action_delay_are_exclusive(make_server):
    with pytest.raises(ValueError, match="action_delay"):
        make_server(run=RunOptions(real_time=True, action_delay=2))


# ---------------------------------------------------------------- batches


def test_step_batch_steps_resets_and_reports_final_observations(make_server):
    server = make_server(3)
    reset = ask(server, "reset_batch", worlds=[0, 1, 2], seeds=[1, 2, 3])
    assert reset["ok"] and reset["obs"].shape == (3, 4)
    single = make_server(1)
    ask(single, "reset", seed=2)
    expected = ask(single, "step", action=1)["obs"]
    ops = [protocol.OP_RESET, protocol.OP_STEP, protocol.OP_STEP_RESET]
    reply = ask(server, "step_batch", ops=ops, actions=np.array([0, 1, 1]))
    assert reply["ok"] and reply["reward"] == [0.0, 1.0, 1.0]
    np.testing.assert_array_equal(reply["obs"][1], expected)
    assert [f[0] for f in reply["final"]] == [2]


@pytest.mark.parametrize(
    "fields, kind",
    [
        ({"worlds": []}, "protocol"),
        ({"worlds": [0, 3]}, "protocol"),
        ({"worlds": [True]}, "protocol"),
        ({"worlds": [0, 1], "seeds": [1]}, "protocol"),
        ({"worlds": [0], "seeds": [-1]}, "protocol"),
        ({"worlds": [0], "options": [1]}, "protocol"),
    ],
)
def test_bad_reset_batch_requests_get_typed_errors(make_server, fields, kind):
    assert error_of(ask(make_server(3), "reset_batch", **fields))["kind"] == kind


@pytest.mark.parametrize(
    "fields, kind",
    [
        ({"ops": [0, 0, 0, 0], "actions": [0, 0, 0, 0]}, "protocol"),
        ({"ops": [0, 9], "actions": [0, 0]}, "protocol"),
        ({"ops": "x" * 100_000, "actions": [0]}, "protocol"),
        ({"ops": [1, 0], "actions": [0, 0]}, "state"),
        ({"ops": [1, 1], "actions": np.array([0, 5])}, "invalid_action"),
        ({"ops": [1, 1], "actions": [0]}, "invalid_action"),
    ],
)
def test_bad_step_batch_requests_get_typed_errors(make_server, fields, kind):
    server = make_server(3)
    err = error_of(ask(server, "step_batch", **fields))
    assert err["kind"] == kind, err
    assert len(err["message"]) < 3 * MAX_ECHO_CHARS
    assert ask(server, "step_batch", ops=[1, 1], actions=[0, 0])["ok"]  # still serving
