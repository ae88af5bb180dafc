"""The compliance checker's pure parts: validators, actions, handshake parsing, report."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.compliance import CHECKS, FAIL, PASS, SKIP, CheckFailed, Result, Target, compliant, format_report
from remoteenv.compliance.handshake_check import handshake_problems, parse_handshake
from remoteenv.compliance.probe_actions import invalid_actions, neutral_action, stacked_actions
from remoteenv.compliance.values import (
    batch_obs_problem,
    envelope_problem,
    frame_problem,
    infos_problem,
    step_reply_problem,
    value_problem,
)
from remoteenv.wire.codec.spaces import space_to_wire
from remoteenv.wire.messages.batch_encoding import columnar_infos

SPACES = [
    spaces.Box(-1.0, 1.0, (2,), dtype=np.float32),
    spaces.Box(-np.inf, np.inf, (3,), dtype=np.float64),
    spaces.Box(0, 10, (2, 2), dtype=np.int32),
    spaces.Discrete(3, start=-1),
    spaces.MultiDiscrete([2, 3]),
    spaces.MultiBinary(4),
    spaces.Dict({"a": spaces.Discrete(2), "b": spaces.Box(0.0, 1.0, (1,), dtype=np.float32)}),
    spaces.Tuple([spaces.Discrete(2), spaces.MultiBinary(2)]),
]


def _handshake(**changes):
    reply = {
        "seq": 1,
        "ok": True,
        "protocol": 1,
        "env_id": "e/v0",
        "instance": 0,
        "pid": 7,
        "num_worlds": 2,
        "observation_space": space_to_wire(SPACES[0]),
        "action_space": space_to_wire(SPACES[3]),
        "metadata": {"render_modes": ["rgb_array"], "render_fps": 50, "dt": 0.02, "timestep": 0.01, "frame_skip": 2},
        "stepping": {"mode": "lock_step", "action_delay": 0},
    }
    reply.update(changes)
    return reply


@pytest.mark.filterwarnings("ignore:.*Casting input x to numpy array")
@pytest.mark.parametrize("space", SPACES, ids=str)
def test_neutral_actions_are_valid_and_invalid_ones_are_not(space):
    action = neutral_action(space)
    assert value_problem(space, action) is None
    assert space.contains(tuple(action) if isinstance(space, spaces.Tuple) else action)
    for label, bad in invalid_actions(space):
        try:
            inside = space.contains(bad)
        except Exception:
            inside = False
        assert not inside, label


def test_stacked_actions_follow_the_batch_wire_form():
    box, discrete = SPACES[0], SPACES[3]
    assert stacked_actions(box, [neutral_action(box)] * 3).shape == (3, 2)
    stacked = stacked_actions(discrete, [neutral_action(discrete)] * 3)
    assert stacked.dtype == np.int64 and stacked.tolist() == [-1, -1, -1]


def test_value_problem_names_dtype_shape_range_and_keys():
    box = SPACES[0]
    assert value_problem(box, np.zeros(2, dtype=np.float32)) is None
    assert "dtype float64" in value_problem(box, np.zeros(2))
    assert "shape (3,)" in value_problem(box, np.zeros(3, dtype=np.float32))
    assert "outside" in value_problem(box, np.full(2, 5, dtype=np.float32))
    assert "must be an array" in value_problem(box, [0.0, 0.0])
    assert "must be an int" in value_problem(SPACES[3], True)
    assert "keys" in value_problem(SPACES[6], {"a": 1})
    assert "obs['b']" in value_problem(SPACES[6], {"a": 1, "b": np.zeros(1)})


def test_envelope_problem():
    assert envelope_problem({"seq": 3, "ok": True}) is None
    assert (
        envelope_problem({"seq": -1, "ok": False, "error": {"kind": "protocol", "message": "m", "traceback": ""}})
        is None
    )
    assert "seq" in envelope_problem({"seq": True, "ok": True})
    assert "'ok'" in envelope_problem({"seq": 1, "ok": 1})
    assert "error.traceback" in envelope_problem({"seq": 1, "ok": False, "error": {"kind": "state", "message": ""}})
    assert "not one of" in envelope_problem(
        {"seq": 1, "ok": False, "error": {"kind": "oops", "message": "", "traceback": ""}}
    )
    assert "map" in envelope_problem([1])


def test_step_reply_problem_wants_a_float_reward_and_bool_flags():
    box = SPACES[0]
    good = {"obs": np.zeros(2, dtype=np.float32), "reward": 1.0, "terminated": False, "truncated": False, "info": {}}
    assert step_reply_problem(box, good) is None
    assert "reward" in step_reply_problem(box, {**good, "reward": 1})
    assert "terminated" in step_reply_problem(box, {**good, "terminated": 0})
    assert "info" in step_reply_problem(box, {**good, "info": None})


def test_infos_problem_accepts_what_the_wire_layer_encodes():
    for infos in ([{"a": 1, "b": 0.5}, {"a": 2}], [{"x": "text"}, {}]):
        assert infos_problem(columnar_infos(infos), 2) is None
    assert "list of 3" in infos_problem({"maps": [{}, {}]}, 3)
    assert "one type" in infos_problem({"columns": {"a": [[1, 0.5], [True, True]]}}, 2)
    assert "present" in infos_problem({"columns": {"a": [[1, 2], [1, 0]]}}, 2)
    assert infos_problem({"columns": {}, "maps": []}, 0) is not None


def test_batch_obs_problem_wants_one_array_for_array_spaces():
    box = SPACES[0]
    assert batch_obs_problem(box, np.zeros((3, 2), dtype=np.float32), 3) is None
    assert "one array" in batch_obs_problem(box, [np.zeros(2, dtype=np.float32)] * 3, 3)
    assert "shape" in batch_obs_problem(box, np.zeros((2, 2), dtype=np.float32), 3)
    assert batch_obs_problem(SPACES[3], [0, 1, -1], 3) is None
    assert "world 1" in batch_obs_problem(SPACES[3], [0, 5, -1], 3)


def test_frame_problem():
    assert frame_problem(None) is None
    assert frame_problem(np.zeros((4, 5, 3), dtype=np.uint8)) is None
    assert frame_problem(np.zeros((4, 5, 4), dtype=np.uint8)) is not None
    assert frame_problem(np.zeros((4, 5, 3))) is not None


def test_handshake_parsing_and_what_it_offers():
    hs = parse_handshake(_handshake())
    assert hs.num_worlds == 2 and hs.observation_space == SPACES[0] and hs.action_space == SPACES[3]
    assert hs.lacks("reset_batch", "step_batch") is None and hs.lacks("timing") is not None
    real_time = parse_handshake(_handshake(stepping={"mode": "real_time"}))
    assert real_time.lacks("timing") is None and "reset_batch" in real_time.lacks("reset_batch")
    listed = parse_handshake(_handshake(commands=["handshake", "reset", "step", "render", "close"]))
    assert "the server's handshake lists" in listed.lacks("step_batch")


def test_handshake_problems_name_every_bad_field():
    problems = handshake_problems(
        _handshake(
            num_worlds=0,
            pid="x",
            observation_space={"type": "Nope"},
            stepping={"mode": "fast"},
            metadata={"render_modes": "rgb_array", "render_fps": 50, "dt": -1, "timestep": 0.01, "frame_skip": 1},
            commands=["handshake"],
        )
    )
    text = " | ".join(problems)
    for field in ("num_worlds", "pid", "observation_space", "stepping", "render_modes", "metadata.dt", "commands"):
        assert field in text
    with pytest.raises(CheckFailed, match="num_worlds"):
        parse_handshake(_handshake(num_worlds=0))


def test_checks_are_named_once_and_ordered_for_a_shared_server():
    names = [c.name for c in CHECKS]
    assert len(set(names)) == len(names)
    assert names.index("step_before_reset") < min(names.index(n) for n in ("reset", "step", "stale_replies"))
    assert names[-1] == "close"
    assert all(c.description and "\n" not in c.description for c in CHECKS)


def test_report_has_a_line_per_check_and_a_verdict():
    target = Target("ipc:///x", source="l.json")
    results = [Result(CHECKS[0], PASS, "note"), Result(CHECKS[1], SKIP, "why"), Result(CHECKS[2], FAIL, "x" * 999)]
    report = format_report(target, results).splitlines()
    assert len(report) == 5 and "l.json" in report[0]
    assert report[1].startswith("PASS") and report[1].endswith(": note")
    assert report[3].startswith("FAIL") and report[3].endswith("...") and len(report[3]) < 600
    assert report[-1] == "1 passed, 1 failed, 1 skipped: NOT COMPLIANT"
    assert not compliant(results) and compliant(results[:2])
