"""A plain step of every world posted in the region is served from the sim's
wait, without the command table's dispatch: the lane takes it straight from
the region's blocks with the usual checks, the table answers it as it
answers any region request, and the wait hands it over only when it came
alone. Any other request is left untaken for the usual way."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fakes import IdleRouter
from gymnasium import spaces

from remoteenv.sim.serving.command_table import CommandTable
from remoteenv.sim.serving.waits import ServingWaits
from remoteenv.sim.transport.channels import PipeChannel
from remoteenv.sim.transport.checks import RequestError
from remoteenv.sim.transport.shared_lane_server import SharedLane
from remoteenv.wire import protocol
from remoteenv.wire.messages.action_rules import BatchCheck
from remoteenv.wire.protocol import OP_RESET, OP_STEP, region_request
from remoteenv.wire.shared_memory.doorbell import REQ_N, Doorbell
from remoteenv.wire.wire_errors import INVALID_ACTION, SCENE, STATE, InvalidAction

ACTION_SPACE = spaces.Box(-1.0, 1.0, (2,), np.float32)
K = 3


class Region:
    """A sim's lane over a real region and pipe, and the agent's doorbell on it."""

    def __init__(self) -> None:
        self.agent_sock, sim_sock = socket.socketpair()
        self.pipe = PipeChannel(sim_sock.detach())
        self.lane = SharedLane(ACTION_SPACE, spaces.Box(-np.inf, np.inf, (4,), np.float64), K)
        self.lane.attach({}, self.pipe, None)
        arrays = self.lane._arrays
        assert arrays is not None and arrays.header is not None
        self.arrays = arrays
        self.agent = Doorbell(arrays.header, silent=True)
        self.check = BatchCheck(ACTION_SPACE)

    def post(self, seq: int, actions: Any, ops: Any = OP_STEP, n: int = K, named: bool = False) -> None:
        """What the agent does: the blocks, then the doorbell's words."""
        self.arrays.ops[:n] = ops
        self.arrays.actions[:n] = actions
        if named:
            self.arrays.worlds[:n] = np.arange(n)
        self.agent.post(seq, n, named, think_s=120e-6)

    def take_plain(self, seq: int) -> np.ndarray | None:
        return self.lane.take_plain(seq, self.pipe, self.check)

    def close(self) -> None:
        self.lane.close()
        self.pipe.close()
        self.agent_sock.close()


@pytest.fixture
def region() -> Iterator[Region]:
    r = Region()
    try:
        yield r
    finally:
        r.close()


ACTIONS = np.array([[0.5, -0.5], [1.0, -1.0], [0.0, 0.25]], dtype=np.float32)


def test_a_plain_step_of_every_world_is_taken_with_its_checked_actions(region: Region) -> None:
    region.post(1, ACTIONS)
    taken = region.take_plain(1)
    assert taken is not None and taken.dtype == np.float32
    np.testing.assert_array_equal(taken, ACTIONS)
    assert region.lane.served == 1
    assert region.lane.agent_think_s == pytest.approx(120e-6)
    region.arrays.actions[:] = 0.0  # a copy: the agent's next request does not change it
    assert taken[1, 0] == 1.0
    assert region.take_plain(1) is None  # served already


@pytest.mark.parametrize(
    "how",
    ["fewer worlds", "worlds named", "a world reset", "an action out of bounds", "a NaN action", "another seq"],
)
def test_any_other_request_is_left_untaken_for_the_usual_way(region: Region, how: str) -> None:
    actions, ops, n, named, seq = ACTIONS, OP_STEP, K, False, 1
    if how == "fewer worlds":
        n, actions = 2, ACTIONS[:2]
    elif how == "worlds named":
        named = True
    elif how == "a world reset":
        ops = np.array([OP_STEP, OP_RESET, OP_STEP])
    elif how == "an action out of bounds":
        actions = ACTIONS * 2
    elif how == "a NaN action":
        actions = ACTIONS.copy()
        actions[2, 1] = np.nan
    region.post(seq, actions, ops, n, named)
    asked = 2 if how == "another seq" else seq
    assert region.take_plain(asked) is None
    assert region.lane.served == 0  # nothing taken
    if how != "another seq":
        taken = region.lane.take(seq, region.pipe)  # the usual way takes it as it always did
        assert taken is not None and taken[0] == list(np.broadcast_to(ops, n))


def test_a_tampered_header_is_left_to_the_usual_way_which_refuses_it(region: Region) -> None:
    region.post(1, ACTIONS)
    region.arrays.header[REQ_N] = 1 << 40  # no request has that many positions
    assert region.take_plain(1) is None
    assert region.lane.served == 0 and region.lane.tampered is None
    with pytest.raises(RequestError) as refused:
        region.lane.take(1, region.pipe)
    assert refused.value.kind == STATE and region.lane.tampered is not None


def test_only_the_launching_agents_pipe_takes_a_plain_step(region: Region) -> None:
    region.post(1, ACTIONS)
    assert region.lane.take_plain(1, None, region.check) is None
    assert region.lane.served == 0


class Plain:
    """Stands in for a :class:`PlainRegionStep`: takes what it is told, steps as told."""

    def __init__(self, taken: np.ndarray | None, step: Any) -> None:
        self.taken, self._step = taken, step
        self.stepped: list[tuple[Any, int]] = []

    def take(self, seq: int, pipe: Any) -> np.ndarray | None:
        return self.taken

    def step(self, actions: np.ndarray, seq: int) -> dict[str, Any] | None:
        self.stepped.append((actions, seq))
        return self._step()


def _raising(exc: Exception) -> Any:
    def step() -> None:
        raise exc

    return step


def test_the_table_answers_a_plain_step_as_it_answers_a_region_request() -> None:
    plain = Plain(ACTIONS, lambda: {"shared": True, "final": []})
    taken, reply = CommandTable({}, plain=plain).handle_plain_region(9, None)  # type: ignore[arg-type]
    assert taken and reply == {"shared": True, "final": [], "seq": 9, "ok": True}
    assert plain.stepped == [(ACTIONS, 9)]
    in_region = Plain(ACTIONS, lambda: None)
    assert CommandTable({}, plain=in_region).handle_plain_region(10, None) == (True, None)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("exc", "kind"),
    [(InvalidAction("bad"), INVALID_ACTION), (RuntimeError("scene bug"), SCENE), (RequestError(STATE, "gone"), STATE)],
)
def test_a_failing_plain_step_gives_the_typed_error_the_usual_way_gives(exc: Exception, kind: str) -> None:
    usual = CommandTable({}, region=lambda msg, pipe: _raising(exc)())
    by_region = usual.handle_region(region_request(4), None)  # type: ignore[arg-type]
    taken, by_plain = CommandTable({}, plain=Plain(ACTIONS, _raising(exc))).handle_plain_region(4, None)  # type: ignore[arg-type]
    assert taken and by_plain is not None and by_region is not None
    assert by_plain["error"]["kind"] == by_region["error"]["kind"] == kind
    assert by_plain["error"]["message"] == by_region["error"]["message"] and by_plain["seq"] == 4


def test_nothing_taken_means_no_answer() -> None:
    assert CommandTable({}).handle_plain_region(3, None) == (False, None)  # type: ignore[arg-type]
    untaken = Plain(None, lambda: {"never": True})
    assert CommandTable({}, plain=untaken).handle_plain_region(3, None) == (False, None)  # type: ignore[arg-type]
    assert untaken.stepped == []


@pytest.mark.parametrize("plain_takes", [True, False])
def test_the_wait_hands_a_region_request_that_came_alone_to_the_plain_server_first(plain_takes: bool) -> None:
    quiet_a, quiet_b = socket.socketpair()
    agent, sim = socket.socketpair()
    pipe = PipeChannel(sim.detach())
    answered: list[Any] = []
    offered: list[int] = []

    def plain(seq: int, channel: PipeChannel) -> bool:
        assert channel is pipe
        offered.append(seq)
        return plain_takes

    try:
        waits = ServingWaits(
            IdleRouter(quiet_a),  # type: ignore[arg-type]
            pipe,
            hot_window_s=0.0,
            spin_s=0.0,
            answer=lambda channel, frames: answered.extend(frames),
            send=lambda outgoing: None,
            pipe_closed=lambda: None,
            plain=plain,
        )
        waits._answer_pipe(pipe, [(None, region_request(5))])
        assert offered == [5]
        assert answered == ([] if plain_takes else [(None, region_request(5))])
        frame = protocol.pack({"seq": 6, "cmd": "ping"})
        waits._answer_pipe(pipe, [(None, frame)])  # a frame: never the plain server's
        both = [(None, frame), (None, region_request(7))]
        waits._answer_pipe(pipe, both)  # sent after a frame: served in the agent's order, the usual way
        assert offered == [5]
        assert answered[-3:] == [(None, frame), *both]
    finally:
        pipe.close()
        for s in (agent, quiet_a, quiet_b):
            s.close()
