"""The agent's wait for a reply in its sim's region with nothing else on the
way (:meth:`~remoteenv.agent.connection.region_watch.RegionWatch.wait_region`),
against a stand-in sim on a socketpair: a reply in the region is taken; a
heads-up is followed; anything else is left, unread or queued, for
``receive``, which then reports or returns it as it always did."""

from __future__ import annotations

import pytest
from fakes import heads_up_once_asked, in_thread, until

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.wire import protocol
from remoteenv.wire.shared_memory import hot_wait
from remoteenv.wire.shared_memory.doorbell import AGENT_HEADS_UP, AGENT_WATCHING
from remoteenv.wire.shared_memory.hot_wait import usable_cpus


def _post_to_block_for(conn, agent_bell, monkeypatch) -> int:
    """Post a plain step whose wait blocks at once and, after the heads-up, waits hot until
    the reply however the threads run (a 30 s window, no stall); its ``seq``."""
    conn._lane_hot.window_s = 0.0
    conn._soon.window_s = 30.0
    monkeypatch.setattr(hot_wait, "STALL_S", 30.0)
    return conn.post(agent_bell, 2, False, plain=True)


def test_a_reply_in_the_region_is_taken_and_its_request_answered(lane):
    conn, agent_bell, _, sim_bell = lane
    seq = conn.post(agent_bell, 2, False, plain=True)
    assert not conn.wait_region(seq + 1)  # another request's: nothing to wait for
    sim_bell.reply(seq, 0)
    assert conn.wait_region(seq)
    assert seq not in conn._unanswered
    assert not conn.wait_region(seq)  # the watch ended with it


def test_an_error_frame_instead_is_left_for_receive_to_raise(lane):
    conn, agent_bell, sim_end, _ = lane
    seq = conn.post(agent_bell, 2, False, plain=True)
    sim_end.sendall(protocol.stream_frame(protocol.pack(protocol.error_reply(seq, "scene", "boom"))))
    assert not conn.wait_region(seq)
    with pytest.raises(RemoteEnvError) as info:
        conn.receive(seq)
    assert info.value.kind == "scene" and "boom" in str(info.value)


def test_the_pipe_s_end_is_left_for_receive_to_report(lane):
    conn, agent_bell, sim_end, _ = lane
    seq = conn.post(agent_bell, 2, False, plain=True)
    sim_end.close()
    assert not conn.wait_region(seq)  # nothing raised here
    with pytest.raises(RemoteEnvError) as info:
        conn.receive(seq)
    assert info.value.kind == "died"


@pytest.mark.skipif(usable_cpus() < 2, reason="no hot waits (nor heads-ups) on one CPU")
def test_a_blocked_wait_follows_the_heads_up_to_the_region_reply(lane, monkeypatch):
    conn, agent_bell, sim_end, sim_bell = lane
    seq = _post_to_block_for(conn, agent_bell, monkeypatch)
    frames: list[bool] = []

    def sim() -> None:
        heads_up_once_asked(sim_bell, sim_end, seq)
        until(lambda: not sim_bell.agent_wants_heads_up())  # woken: watching again
        frames.append(sim_bell.reply(seq, 0))

    thread = in_thread(sim)
    assert conn.wait_region(seq)
    thread.join(5)
    assert frames == [False]  # the woken agent watched: the reply needed no frame
    assert conn.heads_ups == 1 and agent_bell.word(AGENT_HEADS_UP) == 0


@pytest.mark.skipif(usable_cpus() < 2, reason="no hot waits (nor heads-ups) on one CPU")
def test_a_sim_gone_after_its_heads_up_is_left_for_receive_to_report(lane, monkeypatch):
    conn, agent_bell, sim_end, sim_bell = lane
    seq = _post_to_block_for(conn, agent_bell, monkeypatch)

    def sim() -> None:
        heads_up_once_asked(sim_bell, sim_end, seq)
        sim_end.close()  # gone before its reply

    thread = in_thread(sim)
    assert not conn.wait_region(seq)  # nothing raised here: a vector env's restart rule sees it in receive
    thread.join(5)
    assert conn.heads_ups == 1
    with pytest.raises(RemoteEnvError) as info:
        conn.receive(seq)
    assert info.value.kind == "died"


def _wake_up(seq: int) -> bytes:
    """The frame a sim sends with a region reply when the agent was not watching."""
    return protocol.stream_frame(protocol.pack({"region": True, "seq": seq, "ok": True}))


def test_wake_ups_and_heads_ups_of_replies_already_read_are_dropped_and_the_wait_stays_lean(lane):
    conn, agent_bell, sim_end, sim_bell = lane
    first = conn.post(agent_bell, 2, False, plain=True)
    sim_bell.reply(first, 0)
    assert conn.wait_region(first)
    # The reply was read from the region; its wake-up and a late heads-up come after it.
    sim_end.sendall(_wake_up(first) + protocol.stream_frame(protocol.reply_soon(first)))
    second = conn.post(agent_bell, 2, False, plain=True)
    until(lambda: conn._read_quietly(False) and len(conn._frames) == 2)
    sim_bell.reply(second, 0)
    assert conn.wait_region(second)  # not handed back to receive
    assert not conn._frames and second not in conn._unanswered


def test_a_wake_up_read_during_the_wait_is_dropped_once_its_reply_is_in_the_region(lane):
    conn, agent_bell, sim_end, sim_bell = lane
    seq = conn.post(agent_bell, 2, False, plain=True)
    sim_bell.reply(seq, 0)
    sim_end.sendall(_wake_up(seq))
    until(lambda: conn._read_quietly(False) and len(conn._frames) == 1)
    assert conn.wait_region(seq)
    assert not conn._frames


def test_a_frame_that_still_answers_a_request_is_left_for_receive(lane):
    conn, agent_bell, sim_end, sim_bell = lane
    seq = conn.post(agent_bell, 2, False, plain=True)
    # Its own wake-up before the region holds the reply (which the sim never writes):
    # receive must see it, as it sees an error reply.
    sim_end.sendall(_wake_up(seq))
    until(lambda: conn._read_quietly(False) and len(conn._frames) == 1)
    assert not conn.wait_region(seq)
    assert len(conn._frames) == 1


@pytest.mark.skipif(usable_cpus() < 2, reason="no hot waits on one CPU")
@pytest.mark.parametrize("sim_slept", [True, False])
def test_a_wait_that_rang_a_sleeping_sim_does_not_turn_the_lane_s_hot_wait_cold(lane, monkeypatch, sim_slept):
    """A reply later than the hot wait's window turns the next plain waits cold,
    unless the request rang a sim that slept: its wake-up, not the lane, took the time."""
    conn, agent_bell, sim_end, sim_bell = lane
    monkeypatch.setattr(hot_wait, "STALL_S", 30.0)
    conn._lane_hot.window_s = 1e-3
    conn._soon.window_s = 0.0  # blocks without a heads-up
    if not sim_slept:
        sim_bell.sim_watches()
    seq = conn.post(agent_bell, 2, False, plain=True)

    def sim() -> None:
        until(lambda: agent_bell.word(AGENT_WATCHING) == 0)  # the agent blocked after its hot wait
        if sim_bell.reply(seq, 0):
            sim_end.sendall(_wake_up(seq))

    thread = in_thread(sim)
    assert conn.wait_region(seq)
    thread.join(5)
    assert conn._lane_hot.worth_it() is sim_slept
