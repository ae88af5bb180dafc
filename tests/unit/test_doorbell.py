"""The fast lane's doorbell (remoteenv.wire.shared_memory.doorbell): a frame is needed exactly
when the peer may be blocked, a side about to block finds what came meanwhile,
and a loud side (no total store order, or REMOTEENV_LOUD_DOORBELL) always gets
frames, whatever its peer is."""

from __future__ import annotations

import numpy as np

from remoteenv.wire.shared_memory import doorbell
from remoteenv.wire.shared_memory.doorbell import AGENT_WATCHING, REQ_N, REQ_NAMED, REQ_SEQ, SIM_WATCHING, Doorbell


def _pair(agent_silent: bool = True, sim_silent: bool = True) -> tuple[Doorbell, Doorbell, np.ndarray]:
    header = np.zeros(16, dtype="<i8")
    return Doorbell(header, silent=agent_silent), Doorbell(header, silent=sim_silent), header


def test_a_request_needs_its_frame_only_while_the_sim_sleeps() -> None:
    agent, sim, header = _pair()
    assert agent.post(1, 3, True)  # the sim has not watched yet: ring
    assert sim.posted(0) == 1 and tuple(header[[REQ_N, REQ_NAMED]]) == (3, 1)
    assert not sim.reply(1, 0)  # the agent watches: no wake-up frame
    assert agent.answered(1) and not agent.answered(2)
    assert not agent.post(2, 1, False)  # the sim watches since its reply: no frame
    assert sim.posted(1) == 2 and sim.posted(2) == 0
    assert sim.sim_sleeps(2) == 0 and header[SIM_WATCHING] == 0
    assert agent.post(3, 1, False)  # the sim sleeps: ring


def test_a_side_about_to_block_finds_what_came_meanwhile() -> None:
    agent, sim, header = _pair()
    agent.post(1, 1, False)
    assert sim.sim_sleeps(0) == 1 and header[SIM_WATCHING] == 1  # not blocking: watching again
    assert agent.agent_sleeps(2)  # nothing for request 2 yet: block
    assert header[AGENT_WATCHING] == 0
    assert sim.reply(1, 0)  # the agent may be blocked: wake it
    agent.agent_wakes()
    assert header[AGENT_WATCHING] == 1
    assert not agent.agent_sleeps(1) and header[AGENT_WATCHING] == 1  # its reply is there: do not block


def test_a_loud_side_always_gets_frames_from_a_silent_peer() -> None:
    agent, sim, header = _pair(agent_silent=True, sim_silent=False)
    for seq in range(1, 4):
        assert agent.post(seq, 1, False)
        assert sim.posted(seq - 1) == 0  # a loud sim waits for the frame
        assert sim.request()[0] == seq
        assert sim.reply(seq, 0)  # a loud sim always sends its reply's frame
        assert header[SIM_WATCHING] == 0
    agent, sim, header = _pair(agent_silent=False, sim_silent=True)
    for seq in range(1, 4):
        assert agent.post(seq, 1, False)
        sim.posted(seq - 1)
        assert sim.reply(seq, 0)  # the loud agent never watches: wake it with a frame
        assert not agent.answered(seq) and agent.agent_sleeps(seq)  # it reads the frame, not the word
        agent.agent_wakes()
        assert header[AGENT_WATCHING] == 0


def test_the_default_is_read_when_a_doorbell_is_made(monkeypatch) -> None:
    monkeypatch.setattr(doorbell, "SILENT", False)
    assert not Doorbell(np.zeros(16, dtype="<i8")).silent
    monkeypatch.setattr(doorbell, "SILENT", True)
    assert Doorbell(np.zeros(16, dtype="<i8")).silent


def test_a_sequence_word_that_goes_back_is_no_request() -> None:
    agent, sim, header = _pair()
    agent.post(5, 1, False)
    assert sim.posted(0) == 5
    header[REQ_SEQ] = 3  # an agent that rewinds its word would otherwise keep the sim from ever blocking
    assert sim.posted(5) == 0 and sim.sim_sleeps(5) == 0
