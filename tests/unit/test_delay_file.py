"""The delay file that carries a launch's delay specs to its sim: written
exclusively and private, read as a hostile input, long traces included."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest

from remoteenv.agent.launch.sim_command import write_sim_delay_file
from remoteenv.delays import MAX_DELAY_TICKS, Categorical, Constant, Trace, Uniform
from remoteenv.sim.scene_main import apply_channel_flags, apply_delay_file, scene_argument_parser
from remoteenv.wire.delays import delay_file
from remoteenv.wire.delays.delay_file import delay_file_text, read_delay_file, write_delay_file
from remoteenv.wire.delays.delay_specs import MAX_VALUES
from remoteenv.wire.wire_errors import ProtocolError


def long_trace() -> Trace:
    values = np.random.default_rng(0).integers(0, MAX_DELAY_TICKS, size=MAX_VALUES, endpoint=True)
    values[:2] = (MAX_DELAY_TICKS, 0)
    return Trace(values)


def test_a_trace_of_the_documented_maximum_round_trips(tmp_path):
    trace = long_trace()
    link = Categorical([0.001, 0.5], [0.25, 0.75], unit="s")
    text = delay_file_text(trace, Uniform(0, 2), link)
    assert text is not None
    path = tmp_path / "d.json"
    write_delay_file(path, text)
    assert read_delay_file(path) == {"action_delay": trace, "obs_delay": Uniform(0, 2), "link_delay": link}
    assert len(text) > 128 * 1024  # longer than Linux allows one command-line argument


def test_the_file_is_private_and_never_written_through_what_is_there(tmp_path):
    path = tmp_path / "d.json"
    write_delay_file(path, "{}")
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    with pytest.raises(FileExistsError):
        write_delay_file(path, "{}")
    victim = tmp_path / "victim"
    victim.write_text("keep")
    os.symlink(victim, tmp_path / "planted")
    with pytest.raises(FileExistsError):
        write_delay_file(tmp_path / "planted", "{}")
    # A relaunch replaces its instance's file; a symlink planted there is removed, not followed.
    os.symlink(victim, tmp_path / "sim-2.delays.json")
    path2 = write_sim_delay_file(str(tmp_path), 2, delay_file_text(3))
    assert path2 is not None and not os.path.islink(path2)
    assert read_delay_file(path2) == {"action_delay": Constant(3)} and victim.read_text() == "keep"


def test_a_symlink_a_fifo_or_a_directory_is_refused_without_blocking(tmp_path):
    real = tmp_path / "real.json"
    write_delay_file(real, delay_file_text(2) or "")
    os.symlink(real, tmp_path / "link.json")
    with pytest.raises(ProtocolError, match="symlink"):
        read_delay_file(tmp_path / "link.json")
    os.mkfifo(tmp_path / "fifo")  # no writer: a blocking open would hang here
    with pytest.raises(ProtocolError, match="not a regular file"):
        read_delay_file(tmp_path / "fifo")
    with pytest.raises(ProtocolError, match="not a regular file"):
        read_delay_file(tmp_path)
    with pytest.raises(ProtocolError, match="cannot open"):
        read_delay_file(tmp_path / "missing.json")


def test_an_oversized_file_is_refused_before_it_is_parsed(tmp_path, monkeypatch):
    path = tmp_path / "d.json"
    write_delay_file(path, delay_file_text(Trace([1] * 1000)) or "")
    monkeypatch.setattr(delay_file, "MAX_DELAY_FILE_BYTES", 1000)
    with pytest.raises(ProtocolError, match="more than 1000"):
        read_delay_file(path)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (b"\xff{", "not UTF-8 JSON"),
        (b"{", "not UTF-8 JSON"),
        (b"[1, 2]", "must hold a JSON map"),
        (b'{"action_delay": {"kind": "constant", "unit": "ticks", "value": 1}, "x": 1}', "unknown keys"),
        (
            b'{"action_delay": {"kind": "constant", "unit": "s", "value": 0.5}}',
            "action_delay: expected a delay in ticks",
        ),
        (b'{"link_delay": {"kind": "constant", "unit": "ticks", "value": 2}}', "link_delay: expected a delay in s"),
        (b'{"obs_delay": {"kind": "trace", "unit": "ticks", "values": [10001]}}', "obs_delay: invalid trace"),
        (b'{"obs_delay": 3}', "obs_delay: a delay spec must be a map"),
        (b"[" * 100_000 + b"]" * 100_000, "not UTF-8 JSON.*deeper than"),
    ],
)
def test_a_bad_file_is_refused_saying_what_is_wrong(tmp_path, text, match):
    path = tmp_path / "d.json"
    path.write_bytes(text)
    with pytest.raises(ProtocolError, match=match):
        read_delay_file(path)


def test_the_scene_command_line_takes_delays_from_the_file_and_refuses_them_twice(tmp_path, capsys):
    path = write_sim_delay_file(str(tmp_path), 0, delay_file_text(Uniform(1, 4), 2))
    assert path is not None
    parser = scene_argument_parser()
    args = parser.parse_args(["--address", "ipc:///x", "--delay-file", path])
    apply_delay_file(parser, args)
    assert (args.action_delay, args.obs_delay, args.link_delay) == (Uniform(1, 4), Constant(2), None)
    twice = parser.parse_args(["--address", "ipc:///x", "--delay-file", path, "--obs-delay", "1"])
    with pytest.raises(SystemExit):
        apply_delay_file(parser, twice)
    assert "--obs-delay is given twice" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"action_delay": {"kind": "nope"}}))
    with pytest.raises(SystemExit):
        apply_delay_file(parser, parser.parse_args(["--address", "ipc:///x", "--delay-file", str(bad)]))
    assert "unknown delay kind" in capsys.readouterr().err


def test_channel_rules_travel_in_the_file_only_with_a_lock_step_delay_and_are_checked(tmp_path, capsys):
    from remoteenv.wire.delays.channel_rules import ChannelRules

    rules = ChannelRules("in_order", "in_order", True)
    assert delay_file_text(0, 0, None, rules) is None  # no delay: nothing for the rules to act on
    assert "channel" not in (delay_file_text(2, 0, None, ChannelRules()) or "")  # the default is not written
    path = write_sim_delay_file(str(tmp_path), 0, delay_file_text(Uniform(0, 3), 1, None, rules))
    assert path is not None
    assert read_delay_file(path) == {"action_delay": Uniform(0, 3), "obs_delay": Constant(1), "channel": rules}
    parser = scene_argument_parser()
    args = parser.parse_args(["--address", "ipc:///x", "--delay-file", path])
    apply_channel_flags(args)
    assert args.channel is None
    apply_delay_file(parser, args)
    assert args.channel == rules
    flags = parser.parse_args(["--address", "ipc:///x", "--action-delivery", "in_order", "--delayed-rewards"])
    apply_channel_flags(flags)
    assert flags.channel == ChannelRules(action_delivery="in_order", delayed_rewards=True)
    twice = parser.parse_args(["--address", "ipc:///x", "--delay-file", path, "--delayed-rewards"])
    apply_channel_flags(twice)
    with pytest.raises(SystemExit):
        apply_delay_file(parser, twice)
    assert "--delayed-rewards is given twice" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"obs_delay": Constant(1).to_wire(), "channel": {"obs_delivery": "lifo"}}))
    with pytest.raises(ProtocolError, match="channel rules"):
        read_delay_file(bad)
