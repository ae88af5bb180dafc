"""The fast lane's doorbell (remoteenv.wire.shared_memory.doorbell): a frame is needed exactly
when the peer may be blocked, a side about to block finds what came meanwhile,
and a loud side (no total store order, or REMOTEENV_LOUD_DOORBELL) always gets
frames, whatever its peer is."""

from __future__ import annotations

import numpy as np

from remoteenv.wire.shared_memory import doorbell
from remoteenv.wire.shared_memory.doorbell import (
    AGENT_AWAY,
    AGENT_HEADS_UP,
    AGENT_WATCHING,
    REQ_N,
    REQ_NAMED,
    REQ_SEQ,
    SIM_WATCHING,
    Doorbell,
)


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


def test_a_heads_up_is_wanted_only_while_the_agent_sleeps_asking_for_one() -> None:
    agent, sim, header = _pair()
    agent.post(1, 1, False)
    sim.posted(0)
    assert not sim.agent_wants_heads_up()  # awake and watching
    assert agent.agent_sleeps(1)  # blocks without asking
    assert not sim.agent_wants_heads_up()
    agent.agent_wakes()
    assert agent.agent_sleeps(1, heads_up=True)
    assert header[AGENT_HEADS_UP] == 1 and header[AGENT_WATCHING] == 0
    assert sim.agent_wants_heads_up()
    agent.agent_wakes()  # woken (by the heads-up): watching again, no longer asking
    assert header[AGENT_HEADS_UP] == 0 and header[AGENT_WATCHING] == 1
    assert not sim.agent_wants_heads_up()
    assert not sim.reply(1, 0)  # the woken agent watches: the reply needs no frame
    assert agent.agent_tampered() is None and sim.sim_tampered(1) is None


def test_an_agent_whose_reply_is_there_does_not_block_or_ask() -> None:
    agent, sim, header = _pair()
    agent.post(1, 1, False)
    sim.posted(0)
    sim.reply(1, 0)
    assert not agent.agent_sleeps(1, heads_up=True)
    assert header[AGENT_HEADS_UP] == 0 and header[AGENT_WATCHING] == 1


def test_a_loud_agent_never_asks_for_a_heads_up() -> None:
    agent, sim, header = _pair(agent_silent=False)
    agent.post(1, 1, False)
    assert agent.agent_sleeps(1, heads_up=True)
    assert header[AGENT_HEADS_UP] == 0 and not sim.agent_wants_heads_up()
    agent, sim, header = _pair(sim_silent=False)  # a loud sim reads no word without its frame
    agent.post(1, 1, False)
    agent.agent_sleeps(1, heads_up=True)
    assert not sim.agent_wants_heads_up()


def test_a_heads_up_word_off_the_rules_is_tampering() -> None:
    agent, sim, header = _pair()
    agent.post(1, 1, False)
    header[AGENT_HEADS_UP] = 2
    assert "watching flags" in (sim.sim_tampered(0) or "")
    header[AGENT_HEADS_UP] = 1  # the agent asks only while it blocks, never between requests
    assert "heads-up word holds 1" in (agent.agent_tampered() or "")


def test_away_is_said_between_requests_and_cleared_by_the_next() -> None:
    agent, sim, header = _pair()
    agent.post(1, 1, False)
    sim.reply(1, 0)
    assert not sim.agent_away()
    agent.away()
    assert sim.agent_away() and header[AGENT_AWAY] == 1
    assert agent.agent_tampered() is None and sim.sim_tampered(1) is None  # a word the agent may write
    agent.post(2, 1, False)
    assert not sim.agent_away() and header[AGENT_AWAY] == 0


def test_an_away_word_off_the_rules_is_tampering() -> None:
    agent, sim, header = _pair()
    agent.post(1, 1, False)
    header[AGENT_AWAY] = 7
    assert "watching flags" in (sim.sim_tampered(0) or "")
    header[AGENT_AWAY] = 1  # not what the agent wrote last
    assert "away word holds 1" in (agent.agent_tampered() or "")
