"""Parsing a handshake reply into the Handshake dataclass."""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest

from remoteenv.wire.codec.spaces import space_to_wire
from remoteenv.wire.messages.handshake import LOCK_STEP, Handshake, handshake_request, parse_handshake
from remoteenv.wire.protocol import PROTOCOL_VERSION
from remoteenv.wire.wire_errors import ProtocolError

OBS = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
ACT = gym.spaces.Discrete(2)

REPLY = {
    "seq": 1,
    "ok": True,
    "protocol": PROTOCOL_VERSION,
    "env_id": "x/Y-v0",
    "instance": 2,
    "pid": 77,
    "num_worlds": 4,
    "observation_space": space_to_wire(OBS),
    "action_space": space_to_wire(ACT),
    "metadata": {"render_modes": ["rgb_array"], "render_fps": 50, "dt": 0.02, "timestep": 0.01, "frame_skip": 2},
    "stepping": {"mode": "real_time", "real_time_factor": 2.0, "action_delay": 0},
}


def test_a_full_reply():
    hs = parse_handshake(REPLY)
    assert isinstance(hs, Handshake)
    assert hs.observation_space == OBS and hs.action_space == ACT
    assert (hs.env_id, hs.instance, hs.pid, hs.num_worlds) == ("x/Y-v0", 2, 77, 4)
    assert (hs.render_modes, hs.render_fps, hs.dt, hs.timestep, hs.frame_skip) == (("rgb_array",), 50, 0.02, 0.01, 2)
    assert hs.real_time and hs.timed_steps and hs.real_time_factor == 2.0
    assert hs["metadata"]["frame_skip"] == 2  # the reply as received


def test_a_minimal_reply_gets_the_defaults():
    reply = {k: REPLY[k] for k in ("protocol", "observation_space", "action_space")}
    reply["metadata"] = {"render_modes": [], "render_fps": None, "dt": 1}
    hs = parse_handshake(reply)
    assert (hs.env_id, hs.instance, hs.pid, hs.num_worlds, hs.timestep) == (None, 0, None, 1, None)
    assert hs.stepping_mode == LOCK_STEP and not hs.timed_steps and hs.dt == 1.0 and isinstance(hs.dt, float)


def test_an_action_delay_makes_steps_timed():
    reply = copy.deepcopy(REPLY)
    reply["stepping"] = {"mode": "lock_step", "action_delay": 3}
    hs = parse_handshake(reply)
    assert not hs.real_time and hs.timed_steps and hs.action_delay == 3


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda r: r.pop("action_space"), "lacks 'action_space'"),
        (lambda r: r["metadata"].pop("dt"), "lacks metadata 'dt'"),
        (lambda r: r.update(protocol=99), "protocol version 99; this client speaks"),
        (lambda r: r.update(protocol=True), "'protocol' must not be a bool"),
        (lambda r: r.update(instance="two"), "'instance' has the wrong type"),
        (lambda r: r["metadata"].update(render_modes=["a", 3]), "must be strings"),
        (lambda r: r.update(observation_space={"type": "Torus"}), "unknown space type"),
        (lambda r: r.update(action_space={"type": "Discrete"}), "malformed space"),
    ],
)
def test_a_bad_reply_is_a_protocol_error_naming_the_field(change, message):
    reply = copy.deepcopy(REPLY)
    change(reply)
    with pytest.raises(ProtocolError, match=message):
        parse_handshake(reply)


def test_not_a_map():
    with pytest.raises(ProtocolError, match="must be a map"):
        parse_handshake([1, 2])  # type: ignore[arg-type]


def test_the_request():
    assert handshake_request() == {"protocol": PROTOCOL_VERSION}


def test_offered_commands_from_the_list_or_the_stepping_mode():
    listed = parse_handshake({**REPLY, "commands": ["handshake", "reset", "step"]})
    assert listed.commands == frozenset({"handshake", "reset", "step"})
    assert listed.offers("step") and not listed.offers("render") and not listed.offers("timing")
    real_time = parse_handshake(REPLY)
    assert real_time.commands is None
    assert real_time.offers("render") and real_time.offers("timing") and not real_time.offers("step_batch")
    lock_step = parse_handshake({**REPLY, "stepping": {"mode": "lock_step", "action_delay": 0}})
    assert lock_step.offers("step_batch") and lock_step.offers("reset_batch") and not lock_step.offers("timing")
    with pytest.raises(ProtocolError, match="'commands' must be strings"):
        parse_handshake({**REPLY, "commands": ["reset", 5]})


def test_the_world_cost_hint_is_read_and_bounded():
    reply = copy.deepcopy(REPLY)
    assert parse_handshake(reply).world_cost_s is None  # optional
    reply["metadata"]["world_cost_s"] = 6e-4
    assert parse_handshake(reply).world_cost_s == 6e-4
    for bad in (-1.0, 1e9, True, "fast"):
        reply["metadata"]["world_cost_s"] = bad
        with pytest.raises(ProtocolError, match="world_cost_s"):
            parse_handshake(reply)


def test_how_the_physics_steps_is_read_and_bounded():
    reply = copy.deepcopy(REPLY)
    hs = parse_handshake(reply)
    assert hs.physics_threads is None and hs.stacked_hooks is None  # optional
    reply["metadata"].update(physics_threads=2, stacked_hooks=True)
    hs = parse_handshake(reply)
    assert hs.physics_threads == 2 and hs.stacked_hooks is True
    for bad in (0, -1, 10**6, True, "2", 2.0):
        with pytest.raises(ProtocolError, match="physics_threads"):
            parse_handshake({**reply, "metadata": {**reply["metadata"], "physics_threads": bad}})
    for bad in (1, "yes"):
        with pytest.raises(ProtocolError, match="stacked_hooks"):
            parse_handshake({**reply, "metadata": {**reply["metadata"], "stacked_hooks": bad}})


def test_costly_worlds_get_one_process_per_cpu(monkeypatch):
    from remoteenv.agent.vector import vector_layout

    monkeypatch.setattr(vector_layout.os, "cpu_count", lambda: 2)
    layout = vector_layout.default_envs_per_process
    assert layout(8) == layout(8, 12e-6) == layout(8, 50e-6) == 8  # microseconds of physics: one process
    assert layout(16) == 16  # cheap worlds stepped as one batch: one process (test_default_layout_threads below)
    assert layout(16, stacked_hooks=False) == 8  # a scene whose Python runs per world: a process per CPU
    assert layout(8, 6e-4) == 4 and layout(16, 6e-4) == 8 and layout(64, 6e-4) == 32  # camera images: 2 processes
    assert layout(1, 6e-4) == 1 and layout(3, 6e-4) == 2


def test_default_layout_threads(monkeypatch):
    """Cheap worlds worth two physics threads or more run in one process on
    that many threads (at most one per CPU); costly worlds, and layouts of
    several processes, get the sims' own default (None)."""
    from remoteenv.agent.vector import vector_layout

    threads, layout, per = (
        vector_layout.default_physics_threads,
        vector_layout.default_envs_per_process,
        vector_layout.layout_threads,
    )
    monkeypatch.setattr(vector_layout.os, "cpu_count", lambda: 2)
    # One process already up to 8 worlds (1 thread); beyond, one process on both CPUs.
    assert [threads(n) for n in (1, 4, 8, 9, 12, 16, 64, 1024)] == [1, 1, 1, 2, 2, 2, 2, 2]
    assert [layout(n) for n in (1, 4, 8, 9, 12, 16, 64)] == [1, 4, 8, 9, 12, 16, 64]
    assert threads(16, 6e-4) == 1 and layout(16, 6e-4) == 8
    assert threads(12, stacked_hooks=False) == 1 and layout(12, stacked_hooks=False) == 8
    assert per(12, 12) == per(16, 16) == per(64, 64) == 2
    assert per(16, 8) is None and per(8, 8) is None and per(12, 8) is None
    monkeypatch.setattr(vector_layout.os, "cpu_count", lambda: 1)
    assert threads(64) == 1 and layout(64) == 64 and per(64, 64) is None
    monkeypatch.setattr(vector_layout.os, "cpu_count", lambda: 4)
    assert threads(8) == 1 and layout(8) == 8  # a process per CPU would be one process of 8
    assert threads(24) == 4 and layout(24) == 24 and per(24, 24) == 4
    assert threads(64) == 4 and layout(64) == 64
    assert layout(64, 6e-4) == 16 and per(64, 16) is None
