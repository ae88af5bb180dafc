"""FanIn over connections that wait in turn (local pipes): one blocking read per
reply, and a dead sim still reported while another is being waited for."""

from __future__ import annotations

import pytest

from remoteenv.agent.connection.fan_in import FanIn
from remoteenv.agent.connection.sim_connection import SimConnection
from remoteenv.agent.errors import RemoteEnvError, RemoteEnvTimeout
from remoteenv.wire import protocol


class InTurn(SimConnection):
    """Answers request ``seq`` after ``silent`` empty waits; ``dead`` after ``dies_after`` waits of anyone."""

    waits_in_turn = True

    def __init__(self, instance: int, silent: int = 0) -> None:
        super().__init__(f"fake-{instance}", instance=instance, death_check=self._why_dead)
        self.silent = silent
        self.frames: list[bytes] = []
        self.waits = 0
        self.dead = False

    def _why_dead(self) -> str | None:
        return "killed by signal 9" if self.dead else None

    def _send_frame(self, payload: bytes) -> None:
        seq = protocol.unpack(payload)["seq"]
        self.frames.append(protocol.pack({"seq": seq, "ok": True, "from": self.instance}))

    def _recv_frame(self) -> bytes | None:
        self.waits += 1
        if self.silent:
            self.silent -= 1
            return None
        return self.frames.pop(0) if self.frames else None

    def _recv_frame_nowait(self) -> bytes | None:
        return self.frames.pop(0) if self.frames and not self.silent else None


def _send_all(conns: list[InTurn]) -> dict[int, int]:
    return {p: c.send("step_batch") for p, c in enumerate(conns)}


def test_replies_are_read_in_turn_with_one_wait_each():
    conns = [InTurn(0), InTurn(1), InTurn(2)]
    pending, replies = _send_all(conns), {}
    FanIn().gather(conns, pending, "'step_batch'", 5.0, replies)
    assert pending == {}
    assert {p: r["from"] for p, r in replies.items()} == {0: 0, 1: 1, 2: 2}
    assert [c.waits for c in conns] == [1, 1, 1]


def test_a_stale_reply_is_dropped_and_the_awaited_one_returned():
    conns = [InTurn(0), InTurn(1)]
    conns[0].send("step_batch")  # abandoned: its reply is stale
    pending, replies = _send_all(conns), {}
    awaited = dict(pending)
    FanIn().gather(conns, pending, "'step_batch'", 5.0, replies)
    assert awaited[0] == 2 and replies[0]["seq"] == 2 and replies[1]["seq"] == awaited[1]


def test_a_dead_sim_is_reported_while_another_is_awaited():
    slow, dying = InTurn(0, silent=10**6), InTurn(1)
    pending, replies = _send_all([slow, dying]), {}
    dying.dead = True
    with pytest.raises(RemoteEnvError) as err:
        FanIn().gather([slow, dying], pending, "'step_batch'", None, replies)
    assert err.value.kind == "died" and err.value.instance == 1
    assert slow.waits == 1  # noticed after the first empty wait on the slow one


def test_the_whole_call_times_out_naming_the_first_pending_sim():
    conns = [InTurn(0), InTurn(1, silent=10**6)]
    pending, replies = _send_all(conns), {}
    with pytest.raises(RemoteEnvTimeout) as err:
        FanIn().gather(conns, pending, "'step_batch'", 0.0, replies)
    assert err.value.instance == 1 and 0 in replies and list(pending) == [1]


class LyingSim(InTurn):
    """Answers every request as if it had used a shared region it never gave."""

    def _send_frame(self, payload: bytes) -> None:
        seq = protocol.unpack(payload)["seq"]
        self.frames.append(protocol.pack({"seq": seq, "ok": True, "shared": True, "info": {"columns": {}}}))


def test_a_shared_reply_to_a_request_sent_over_the_wire_is_a_protocol_error():
    from types import SimpleNamespace

    import numpy as np
    from gymnasium.spaces import Box

    from remoteenv.agent.connection.reply_checks import ReplyChecks
    from remoteenv.agent.launch.restart import RestartBudget
    from remoteenv.agent.vector.vector_requests import VectorRequests
    from remoteenv.agent.vector.vector_results import ObsBatch

    conns = [LyingSim(0)]
    obs_space = Box(-1.0, 1.0, (1,), np.float32)
    session = SimpleNamespace(
        conns=conns,
        handshake=SimpleNamespace(observation_space=obs_space),
        checks=ReplyChecks(obs_space),
        handshakes=[SimpleNamespace(offers=lambda cmd: cmd != "shared_batch")],  # no region offered
        restarts=RestartBudget(False, 0),
        timeout_for=lambda cmd: 5.0,
    )
    requests = VectorRequests(session, [(0, 2)], real_time=False, same_step=False)  # type: ignore[arg-type]
    ops = np.zeros(2, dtype=np.int64)
    pending = requests.start_step(ops, np.zeros((2, 1), np.float32))
    with pytest.raises(RemoteEnvError) as err:
        requests.finish_step(pending, ops, None, None, ObsBatch(None, 2))  # type: ignore[arg-type]
    assert err.value.kind == "protocol" and "shared region" in str(err.value)
