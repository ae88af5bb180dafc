"""Issue 28, item 2: the latency study's ``--resume`` file is read through the
bounded reader and its records are checked against the study's design before
any is kept; a file that fails is refused with an error naming it."""

from __future__ import annotations

import json
import math
import os
import threading

import pytest

from remoteenv.latency.study.design import StudyConfig, cells
from remoteenv.latency.study.results import load_records, write_json

CONFIG = StudyConfig(delays=(0, 2), random_delays=("U(1,4)",), seeds=(0, 1), steps=64, eval_episodes=2)


def _record(cell, returns=(100.0, 120.0)):
    return {
        "variant": cell.variant,
        "kind": cell.kind,
        "delay": cell.delay,
        "seed": cell.seed,
        "mean_return": sum(returns) / len(returns),
        "returns": list(returns),
        "history_length": cell.history_length,
        "include_alpha": cell.include_alpha,
        "steps": CONFIG.steps,
        "train_s": 3.5,
        "train_return": 80.0,
        "curve": [[64.0, 20.0], [128.0, float("nan")]],
    }


def _write(path, records, config=CONFIG):
    write_json(str(path), {"config": config.to_json(), "records": records})


def _refused(path, *words):
    with pytest.raises(ValueError) as caught:
        load_records(str(path), CONFIG)
    message = str(caught.value)
    assert str(path) in message and "\n" not in message, message
    for word in words:
        assert word in message, message
    return message


def test_the_records_of_this_study_are_kept(tmp_path):
    path = tmp_path / "delay_effect.json"
    records = [_record(cell) for cell in cells(CONFIG)]
    _write(path, records)
    kept = load_records(str(path), CONFIG)
    assert [(r["variant"], r["kind"], r["delay"], r["seed"]) for r in kept] == [c.key for c in cells(CONFIG)]


def test_a_fifo_is_refused_at_once(tmp_path):
    path = tmp_path / "delay_effect.json"
    os.mkfifo(path)
    outcome: list[BaseException | None] = []

    def load():
        try:
            load_records(str(path), CONFIG)
            outcome.append(None)
        except BaseException as exc:
            outcome.append(exc)

    reader = threading.Thread(target=load, daemon=True)
    reader.start()
    reader.join(30.0)
    if reader.is_alive():  # unblock the reader so no thread is left behind
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        reader.join(5.0)
        pytest.fail("reading a FIFO as the resume file blocked")
    assert isinstance(outcome[0], ValueError) and "not a regular file" in str(outcome[0])


def test_a_symlink_to_dev_zero_is_refused(tmp_path):
    path = tmp_path / "delay_effect.json"
    os.symlink("/dev/zero", path)
    _refused(path, "not a regular file")


def test_deep_nesting_is_refused(tmp_path):
    path = tmp_path / "delay_effect.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    _refused(path, "deeper")


def test_a_file_that_is_not_json_is_refused(tmp_path):
    path = tmp_path / "delay_effect.json"
    path.write_bytes(b"\xff\xfe not json")
    _refused(path)


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda r: r.pop("kind"), ["kind"]),
        (lambda r: r.update(delay="2"), ["delay", "not a int"]),
        (lambda r: r.update(seed=True), ["seed"]),
        (lambda r: r.update(returns=None), ["returns"]),
        (lambda r: r.update(returns=[1.0]), ["returns", "2 episodes"]),
        (lambda r: r.update(returns=[1.0, "x"]), ["return"]),
        (lambda r: r.update(mean_return=5.0), ["mean_return", "mean of its returns"]),
        (lambda r: r.update(steps=10**9), ["steps"]),
        (lambda r: r.update(history_length=7), ["history_length"]),
        (lambda r: r.update(curve=[[1.0]]), ["curve"]),
        (lambda r: r.update(train_s=-1.0), ["train_s"]),
    ],
    ids=[
        "missing",
        "string-delay",
        "bool-seed",
        "null-returns",
        "short",
        "text",
        "mean",
        "steps",
        "history",
        "curve",
        "time",
    ],
)
def test_a_malformed_record_is_refused(tmp_path, change, words):
    path = tmp_path / "delay_effect.json"
    records = [_record(cell) for cell in cells(CONFIG)]
    change(records[1])
    _write(path, records)
    _refused(path, "record 1", *words)


@pytest.mark.parametrize(
    "field, value",
    [("kind", "gaussian"), ("variant", "oracle"), ("delay", 3), ("seed", 9)],
)
def test_a_cell_outside_the_design_is_refused(tmp_path, field, value):
    path = tmp_path / "delay_effect.json"
    record = _record(next(iter(cells(CONFIG))))
    record[field] = value
    _write(path, [record])
    _refused(path, "not in this study's design")


def test_a_cell_twice_is_refused(tmp_path):
    path = tmp_path / "delay_effect.json"
    cell = next(iter(cells(CONFIG)))
    _write(path, [_record(cell), _record(cell)])
    _refused(path, "twice")


@pytest.mark.parametrize("value", [1e308, math.nan, math.inf, 501.0, -1.0], ids=["1e308", "nan", "inf", "501", "-1"])
def test_every_cell_claimed_done_with_returns_the_scene_cannot_give_is_refused(tmp_path, value):
    """CartPole's return lies in 0..500 (+1 per tick, 500-tick limit)."""
    path = tmp_path / "delay_effect.json"
    _write(path, [_record(cell, returns=(value, value)) for cell in cells(CONFIG)])
    _refused(path, "record 0")


def test_a_file_of_another_configuration_is_refused(tmp_path):
    path = tmp_path / "delay_effect.json"
    _write(path, [], config=StudyConfig(delays=(0,), random_delays=(), seeds=(0,), steps=64))
    _refused(path, "another configuration")


def test_a_records_value_that_is_not_a_list_is_refused(tmp_path):
    path = tmp_path / "delay_effect.json"
    path.write_text(json.dumps({"config": CONFIG.to_json(), "records": {"a": 1}}))
    _refused(path, "not a list")


def test_a_saved_policy_is_read_through_the_bounded_reader(tmp_path):
    """A FIFO where a policy should be (``--policies`` is the user's) is refused, not waited on."""
    pytest.importorskip("stable_baselines3")
    from remoteenv.latency.study.training import TrainedPolicy

    os.mkfifo(tmp_path / "plain-constant-0-seed0.zip")
    with pytest.raises(ValueError, match="not a regular file"):
        TrainedPolicy.load(str(tmp_path / "plain-constant-0-seed0"))
