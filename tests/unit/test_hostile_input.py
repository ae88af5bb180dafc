"""Issue 19, the pure parts: what a hostile peer sends the agent is bounded
and checked before use. Space maps and replies counted before they are
built, every reply checked against the handshake (vectorised for batches),
error replies capped, connections to garbage endpoints refused with a
``LaunchError``; the file reader's own bounds. No process is started here
(see also ``test_hostile_files.py`` and ``test_shared_region_seals.py``)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.agent.connection.reply_checks import ReplyChecks
from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.connection.zmq_connection import ZmqConnection
from remoteenv.agent.errors import LaunchError, RemoteEnvError, RemoteProtocolError
from remoteenv.agent.vector.vector_layout import check_sims
from remoteenv.wire import protocol
from remoteenv.wire.codec.scalar_types import restore_scalars
from remoteenv.wire.codec.spaces import space_from_wire, space_to_wire
from remoteenv.wire.codec.value_count import values_within
from remoteenv.wire.files.file_reads import UnreadableFile, parse_json, read_bytes
from remoteenv.wire.messages.handshake import parse_handshake
from remoteenv.wire.wire_errors import ProtocolError

OBS = spaces.Box(-1.0, 1.0, (3,), np.float32)


# ---------------------------------------------------------------- space maps and handshakes


def _handshake(obs: dict, num_worlds: int = 1) -> dict:
    return {
        "protocol": protocol.PROTOCOL_VERSION,
        "num_worlds": num_worlds,
        "observation_space": obs,
        "action_space": space_to_wire(spaces.Discrete(2)),
        "metadata": {"render_modes": [], "render_fps": None, "dt": 0.02},
    }


@pytest.mark.parametrize(
    "desc, message",
    [
        ({"type": "MultiBinary", "n": [10**9]}, "frame limit"),
        ({"type": "Dict", "spaces": {f"k{i}": {"type": "Discrete", "n": 2} for i in range(2000)}}, "more than 1024"),
        ({"type": "Discrete", "n": 2**64 - 1}, "within int64"),
        ({"type": "Discrete", "n": 0}, "n >= 1"),
        ({"type": "Box", "low": np.zeros(2), "high": np.ones(2), "dtype": "V16"}, "dtype"),
        ({"type": "Box", "low": 0.0, "high": 1.0, "dtype": "<f4"}, "arrays"),
        ({"type": "Tuple", "spaces": "no"}, "list of spaces"),
        ({"type": "Dict", "spaces": {"a": 3}}, "space map"),
        ({"type": "MultiDiscrete", "nvec": np.array([1.5]), "dtype": "<i8"}, "array of ints"),
    ],
)
def test_a_hostile_space_map_is_refused_before_a_space_is_built(desc, message):
    with pytest.raises(ProtocolError, match=message):
        space_from_wire(desc)


def test_deep_nesting_is_refused_without_recursing():
    desc: dict = {"type": "Discrete", "n": 2}
    for _ in range(5000):  # far beyond Python's recursion limit
        desc = {"type": "Tuple", "spaces": [desc]}
    with pytest.raises(ProtocolError, match="deeper than 16"):
        space_from_wire(desc)


def test_spaces_of_the_spec_still_travel():
    for space in (
        OBS,
        spaces.Discrete(5, start=-2),
        spaces.MultiDiscrete([3, 4]),
        spaces.MultiBinary([2, 3]),
        spaces.Dict({"a": OBS, "b": spaces.Tuple([spaces.Discrete(2), OBS])}),
        spaces.Box(0, 255, (1080, 1920, 3), np.uint8),  # a 1080p image space (low and high travel too)
    ):
        wire = protocol.unpack(protocol.pack(space_to_wire(space)))
        assert space_from_wire(wire) == space


def test_num_worlds_is_bounded_and_every_worlds_obs_must_fit_one_frame():
    obs = space_to_wire(OBS)
    with pytest.raises(ProtocolError, match="num_worlds"):
        parse_handshake(_handshake(obs, 10**9))
    big = space_to_wire(spaces.Box(0, 255, (1024, 1024, 3), np.uint8))  # 3 MiB per world
    assert parse_handshake(_handshake(big, 10)).num_worlds == 10
    with pytest.raises(ProtocolError, match="no batch reply could carry them"):
        parse_handshake(_handshake(big, 11))


# ---------------------------------------------------------------- counting values before decoding


def test_a_frame_of_more_values_than_the_limit_is_refused_undecoded():
    n = 3_000
    bomb = b"\x81\xa4bomb\xdd" + struct.pack(">I", n) + b"\x80" * n  # {"bomb": [{}, {}, ...]}
    assert not values_within(bomb, 1_000)
    with pytest.raises(ProtocolError, match="more than 1000 msgpack values"):
        protocol.unpack(bomb, max_values=1_000)
    assert len(protocol.unpack(bomb)["bomb"]) == n


@pytest.mark.parametrize(
    "value",
    [
        {"seq": 3, "ok": True, "obs": np.zeros((64, 10), np.float32), "reward": [1.5] * 64},
        [1, -3, -100, 2**40, -(2**40), 1.5, None, True, "x" * 40, b"y" * 300, "z" * 70_000, {"a": {}}],
        {str(i): [i] * 20 for i in range(50)},
    ],
)
def test_the_count_matches_what_decoding_builds(value):
    frame = protocol.pack(value)

    def count(v: object) -> int:
        if isinstance(v, dict):
            return 1 + sum(count(k) + count(x) for k, x in v.items())
        if isinstance(v, list):
            return 1 + sum(count(x) for x in v)
        return 1

    n = count(protocol.unpack(frame))
    if len(frame) > n - 1:  # the count is walked only when the frame is longer than the limit
        assert values_within(frame, n) and not values_within(frame, n - 1)


# ---------------------------------------------------------------- replies checked against the handshake


class Conn:
    instance = 2
    endpoint = "tcp://127.0.0.1:5555"


def _batch(n: int = 4) -> dict:
    return {
        "seq": 1,
        "ok": True,
        "obs": np.zeros((n, 3), np.float32),
        "reward": [1.0] * n,
        "terminated": [False] * n,
        "truncated": [False] * n,
        "info": {"columns": {"x": [[0.5] * n, [True] * n]}},
        "final": [],
    }


@pytest.mark.parametrize(
    "change, field",
    [
        (lambda r: r.update(reward=[1.0]), "reward"),  # 1 reward for 4 worlds
        (lambda r: r.update(reward=["1.0"] * 4), "reward"),
        (lambda r: r.update(reward=[True] * 4), "reward"),
        (lambda r: r.pop("reward"), "reward"),
        (lambda r: r.update(terminated=[0, 2, 0, 0]), "terminated"),
        (lambda r: r.update(terminated=[None] * 4), "terminated"),
        (lambda r: r.update(truncated="no"), "truncated"),
        (lambda r: r.update(obs=np.zeros((4, 3), np.float64)), "obs"),
        (lambda r: r.update(obs=np.zeros((3, 3), np.float32)), "obs"),
        (lambda r: r.update(obs=[[0.0, 0.0, 0.0]] * 4), "obs"),
        (lambda r: r.update(final=[[-1, np.zeros(3, np.float32), {}]]), "final"),  # the last world, silently
        (lambda r: r.update(final=[[4, np.zeros(3, np.float32), {}]]), "final"),
        (lambda r: r.update(final=[[0, np.zeros(3, np.float32), {}]] * 2), "final"),
        (lambda r: r.update(final=[[0, np.zeros(3, np.float64), {}]]), "final"),
        (lambda r: r.update(final=[[0, np.zeros(3, np.float32)]]), "final"),
        (lambda r: r.update(info={"columns": {"x": [[0.5], [True]]}}), "info"),
        (lambda r: r.update(info={"columns": {"x": [["a"] * 4, [True] * 4]}}), "info"),
        (lambda r: r.update(info={"maps": [{}] * 3}), "info"),
        (lambda r: r.update(info={"maps": [{b"k": 1}] * 4}), "info"),
        (lambda r: r.update(info=["a"]), "info"),
        (lambda r: r.update(final_types="x"), "final_types"),
    ],
)
def test_a_batch_reply_off_the_handshake_names_command_field_and_sim(change, field):
    reply = _batch()
    change(reply)
    with pytest.raises(RemoteProtocolError) as err:
        ReplyChecks(OBS).batch(Conn(), "step_batch", reply, 4)
    message = str(err.value)
    assert f"'{field}'" in message and "'step_batch'" in message and "sim instance 2 at tcp://127.0.0.1:5555" in message
    assert err.value.instance == 2


def test_a_good_batch_reply_comes_back_with_arrays_for_its_lists():
    reply = ReplyChecks(OBS).batch(Conn(), "step_batch", _batch(), 4)
    assert reply["reward"].dtype == np.float64 and reply["terminated"].dtype == np.bool_
    values, present = reply["info"]["columns"]["x"]
    assert values.shape == (4,) and present.dtype == np.bool_


@pytest.mark.parametrize(
    "space, good, bad",
    [
        (spaces.Discrete(3, start=1), 3, [0, 4, True, 1.0, "1"]),
        (spaces.Dict({"a": OBS}), {"a": np.zeros(3, np.float32)}, [{"b": np.zeros(3, np.float32)}, [1]]),
        (spaces.Tuple([spaces.Discrete(2), OBS]), [1, np.zeros(3, np.float32)], [[1], [1, np.zeros(2, np.float32)]]),
        (spaces.MultiBinary(3), np.zeros(3, np.int8), [np.zeros(3, np.int64), [0, 1, 0]]),
    ],
)
def test_single_observations_of_every_space_are_checked(space, good, bad):
    checks = ReplyChecks(space)
    step = {"reward": 1.0, "terminated": False, "truncated": False, "info": {}}
    checks.step(Conn(), {"obs": good, **step})
    for obs in bad:
        with pytest.raises(RemoteProtocolError, match="'obs'"):
            checks.step(Conn(), {"obs": obs, **step})


@pytest.mark.parametrize(
    "reply, field",
    [
        ({"reward": "1", "terminated": False, "truncated": False, "info": {}}, "reward"),
        ({"reward": True, "terminated": False, "truncated": False, "info": {}}, "reward"),
        ({"reward": 1.0, "terminated": "no", "truncated": False, "info": {}}, "terminated"),
        ({"reward": 1.0, "terminated": False, "truncated": False, "info": []}, "info"),
        ({"reward": 1.0, "terminated": False, "truncated": False}, "info"),
    ],
)
def test_a_step_reply_needs_a_number_reward_bool_flags_and_an_info_map(reply, field):
    with pytest.raises(RemoteProtocolError, match=f"'{field}'"):
        ReplyChecks(OBS).step(Conn(), {"obs": np.zeros(3, np.float32), **reply})


def test_frames_attributes_and_sim_times_are_checked():
    checks = ReplyChecks(OBS)
    checks.frame(Conn(), {"frame": None})
    checks.frame(Conn(), {"frame": np.zeros((2, 2, 3), np.uint8)})
    for frame in ("pixels", np.zeros((2, 2, 3), np.float32), np.zeros((2, 2), np.uint8)):
        with pytest.raises(RemoteProtocolError, match="'frame'"):
            checks.frame(Conn(), {"frame": frame})
    with pytest.raises(RemoteProtocolError, match="'value'"):
        checks.attribute(Conn(), "get_attr", {"callable": False})
    with pytest.raises(RemoteProtocolError, match="'result'"):
        checks.attribute(Conn(), "call", {})
    with pytest.raises(RemoteProtocolError, match="'sim_time'"):
        checks.sim_times(Conn(), "pause", {"sim_time": ["t"]}, 1)


def test_a_types_hint_that_does_not_fit_leaves_the_value_as_sent():
    reply = restore_scalars({"reward": 1000, "info": {"n": -5}, "types": {"reward": "|i1", "info": {"n": "|u1"}}})
    assert reply["reward"] == 1000 and type(reply["reward"]) is int and reply["info"]["n"] == -5
    reply = restore_scalars({"reward": 1e300, "types": {"reward": "<f2"}})
    assert reply["reward"] == 1e300 and type(reply["reward"]) is float


def test_sims_of_one_vector_env_must_declare_the_same_spaces():
    first = parse_handshake(_handshake(space_to_wire(OBS)))
    other = parse_handshake({**_handshake(space_to_wire(spaces.Box(-1, 1, (4,), np.float32))), "instance": 1})
    with pytest.raises(RemoteEnvError, match="unlike sim instance 0"):
        check_sims([first, other], [(0, 1), (1, 2)], batches=False)


# ---------------------------------------------------------------- error replies and connections


class Frames(SimConnection):
    """A connection whose transport hands over prepared frames."""

    def __init__(self, frames: list[bytes]) -> None:
        super().__init__("tcp://127.0.0.1:5555", instance=1, timeout=5.0)
        self.frames = frames

    def _send_frame(self, payload: bytes) -> None:
        pass

    def _recv_frame(self) -> bytes | None:
        return self.frames.pop(0) if self.frames else None

    _recv_frame_nowait = _recv_frame


@pytest.mark.parametrize(
    "reply, message",
    [
        ({"seq": 1, "ok": False, "error": "boom"}, "neither 'ok': true nor an error map"),
        ({"seq": 1, "obs": 1}, "neither 'ok': true nor an error map"),
        ({"seq": 1, "ok": 1}, "neither 'ok': true nor an error map"),
    ],
)
def test_an_error_reply_without_an_error_map_is_a_protocol_error(reply, message):
    conn = Frames([protocol.pack(reply)])
    with pytest.raises(RemoteProtocolError, match=message):
        conn.request("step")


def test_a_huge_error_message_is_capped_where_it_is_received():
    error = {"kind": "scene" * 100, "message": "m" * 5_000_000, "traceback": "t" * 5_000_000}
    conn = Frames([protocol.pack({"seq": 1, "ok": False, "error": error})])
    with pytest.raises(RemoteEnvError) as err:
        conn.request("step")
    assert len(str(err.value)) < 2 * protocol.MAX_ERROR_CHARS + 300 and err.value.kind == "remote"


def test_a_server_cannot_pass_its_error_off_as_the_agents_own_kinds():
    error = {"kind": "died", "message": "gone", "traceback": ""}
    conn = Frames([protocol.pack({"seq": 1, "ok": False, "error": error})])
    with pytest.raises(RemoteEnvError) as err:
        conn.request("step")
    assert type(err.value) is RemoteEnvError and err.value.kind == "remote" and "(died)" in str(err.value)


def test_try_receive_reads_a_bounded_number_of_stale_frames_per_call():
    stale = [protocol.pack({"seq": 99, "ok": True})] * 500
    conn = Frames(stale)
    conn.send("step")
    assert conn.try_receive(1) is None and len(conn.frames) == 500 - 64


@pytest.mark.parametrize("endpoint", ["garbage", "tcp://", "bogus://x", "ipc://" + "x" * 5000])
def test_a_garbage_endpoint_is_a_launch_error_not_a_zmq_error(endpoint):
    with pytest.raises(LaunchError, match="not one ZeroMQ can reach") as err:
        ZmqConnection(endpoint)
    assert len(str(err.value)) < 600


def test_a_garbage_curve_key_is_a_launch_error():
    with pytest.raises(LaunchError, match="server public key"):
        ZmqConnection("tcp://127.0.0.1:5555", curve_server_key=b"not a key")


# ---------------------------------------------------------------- the file reader


def test_a_file_above_its_bound_is_refused(tmp_path):
    big = tmp_path / "big"
    big.write_bytes(b"x" * 2048)
    with pytest.raises(UnreadableFile, match="more than the 1024"):
        read_bytes(big, 1024)
    assert read_bytes(big, 2048) == b"x" * 2048


def test_json_depth_skips_brackets_in_strings():
    assert parse_json('["[[[", {"a": "\\"]]"}]') == ["[[[", {"a": '"]]'}]
    with pytest.raises(UnreadableFile, match="deeper than 2"):
        parse_json("[[[1]]]", max_depth=2)
