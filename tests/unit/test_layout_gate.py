"""The layout gate's file, read as a sim's word: bounded, every field checked."""

from __future__ import annotations

import json

import pytest

from remoteenv.agent.errors import RemoteEnvError
from remoteenv.agent.launch.layout_gate import GATE_FILE_LIMIT, GateFacts, parse_facts, wait_facts
from remoteenv.wire.codec.frame_limits import MAX_WORLDS

PID = 4242
GOOD = {"world_cost_s": 3.2e-05, "stacked_hooks": True, "worlds_that_fit": 1000, "pid": PID}


def test_a_well_formed_file_gives_its_facts():
    assert parse_facts(GOOD, PID) == GateFacts(3.2e-05, True, 1000)
    assert parse_facts({**GOOD, "world_cost_s": None, "worlds_that_fit": 0}, PID) == GateFacts(None, True, 0)
    assert parse_facts({**GOOD, "world_cost_s": 1}, PID).cost_s == 1.0
    assert parse_facts({**GOOD, "worlds_that_fit": 10**12}, PID).fit == MAX_WORLDS


@pytest.mark.parametrize(
    "doc, says",
    [
        ([1, 2], "JSON object"),
        ({**GOOD, "pid": PID + 1}, "not by the sim"),
        ({k: v for k, v in GOOD.items() if k != "pid"}, "not by the sim"),
        ({**GOOD, "world_cost_s": -1.0}, "world_cost_s"),
        ({**GOOD, "world_cost_s": float("inf")}, "world_cost_s"),
        ({**GOOD, "world_cost_s": True}, "world_cost_s"),
        ({**GOOD, "world_cost_s": "0.1"}, "world_cost_s"),
        ({**GOOD, "stacked_hooks": 1}, "stacked_hooks"),
        ({**GOOD, "stacked_hooks": None}, "stacked_hooks"),
        ({**GOOD, "worlds_that_fit": -1}, "worlds_that_fit"),
        ({**GOOD, "worlds_that_fit": 2.0}, "worlds_that_fit"),
        ({**GOOD, "worlds_that_fit": False}, "worlds_that_fit"),
    ],
)
def test_a_malformed_file_is_refused_saying_what_is_wrong(doc, says):
    with pytest.raises(ValueError, match=says):
        parse_facts(doc, PID)


def test_the_message_quotes_a_bad_value_short():
    with pytest.raises(ValueError) as info:
        parse_facts({**GOOD, "stacked_hooks": "x" * 10_000}, PID)
    assert len(str(info.value)) < 200


class FakeSim:
    instance = 0
    ready_file = ""
    endpoint = None

    def __init__(self, pid: int = PID, dead: str | None = None) -> None:
        self.pid = pid
        self.dead = dead

    def death(self) -> str | None:
        return self.dead

    def stderr_tail(self, lines: int = 20) -> str:
        return "its stderr"


def test_waiting_reads_the_file_once_it_is_there(tmp_path):
    path = tmp_path / "sim-0.layout.json"
    path.write_text(json.dumps(GOOD))
    assert wait_facts(FakeSim(), str(path), 5.0, "scene.py") == GateFacts(3.2e-05, True, 1000)


def test_a_malformed_file_fails_the_launch_naming_the_sim(tmp_path):
    path = tmp_path / "sim-0.layout.json"
    path.write_text(json.dumps({**GOOD, "stacked_hooks": "yes"}))
    with pytest.raises(RemoteEnvError, match=r"sim instance 0 \(pid 4242\) of scene.py wrote a malformed"):
        wait_facts(FakeSim(), str(path), 5.0, "scene.py")


def test_an_oversized_file_is_not_read_whole(tmp_path):
    path = tmp_path / "sim-0.layout.json"
    path.write_text(json.dumps({**GOOD, "pad": "x" * GATE_FILE_LIMIT}))
    with pytest.raises(RemoteEnvError, match="malformed layout gate file") as info:
        wait_facts(FakeSim(), str(path), 5.0, "scene.py")
    assert len(str(info.value)) < 1000


def test_a_sim_that_dies_before_writing_fails_the_launch(tmp_path):
    with pytest.raises(RemoteEnvError, match="scene.py"):
        wait_facts(FakeSim(dead="exit code 1"), str(tmp_path / "none.json"), 5.0, "scene.py")


def test_a_sim_that_never_writes_times_out_with_the_fix(tmp_path):
    with pytest.raises(RemoteEnvError, match="raise startup_timeout="):
        wait_facts(FakeSim(), str(tmp_path / "none.json"), 0.05, "scene.py")
