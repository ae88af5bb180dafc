"""The delay-effect study's grid, configuration and results helpers (no training here)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from remoteenv.delays import Uniform
from remoteenv.latency.study.design import PPO_SETTINGS, Cell, StudyConfig, cells, random_model
from remoteenv.latency.study.results import load_records, markdown_table, summarize, write_json


def test_cells_cover_every_variant_delay_and_seed_once_in_a_fixed_order():
    config = StudyConfig(delays=(0, 8), random_delays=("U(6,10)",), seeds=(0, 1))
    grid = list(cells(config))
    # history at constant 0 sees no action (none in flight): it is plain, not trained twice
    assert len(grid) == (1 + 2 + 2) * 2
    assert Cell("history", "constant", 0, 0) not in grid
    assert len({c.key for c in grid}) == len(grid)
    assert grid[0] == Cell("plain", "constant", 0, 0)
    assert grid[-1] == Cell("history", "random", "U(6,10)", 1)
    assert list(cells(config)) == grid


def test_a_cell_says_what_the_policy_sees_and_which_delay_the_env_gets():
    assert Cell("plain", "constant", 8, 0).history_length == 0
    assert Cell("history", "constant", 8, 0).history_length == 8
    assert Cell("history", "random", "U(6,10)", 0).history_length == 11  # the in-force action at age 10 too
    assert not Cell("history", "constant", 8, 0).include_alpha
    assert Cell("history", "random", "U(6,10)", 0).include_alpha
    assert not Cell("plain", "random", "U(6,10)", 0).include_alpha
    assert Cell("history", "constant", 0, 0).uses_wrapper is False
    assert Cell("plain", "constant", 4, 0).delay_spec() == 4
    assert Cell("plain", "random", "U(6,10)", 0).delay_spec() == Uniform(6, 10)


@pytest.mark.parametrize("name", ["U(6, 10)", "U(10,6)", "Uniform(0,8)", "U(-1,3)", 8])
def test_a_random_model_is_named_low_high_in_ticks(name):
    with pytest.raises(ValueError):
        random_model(name)
    with pytest.raises(ValueError):
        StudyConfig(random_delays=(name,))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"delays": (-1,)},
        {"seeds": ()},
        {"delays": (), "random_delays": ()},
        {"steps": 0},
        {"eval_episodes": 0},
        {"ppo": {"learning_rat": 1e-3}},
        {"delays": (True,)},
        {"delays": (8, 8)},
        {"random_delays": ("U(0,8)", "U(0,8)")},
    ],
)
def test_a_bad_configuration_is_refused(kwargs):
    with pytest.raises(ValueError):
        StudyConfig(**kwargs)


def test_the_configuration_round_trips_through_json_and_keeps_the_ppo_overrides():
    config = StudyConfig(delays=(0, 4), random_delays=(), seeds=(3,), steps=1000, ppo={"gamma": 0.99})
    again = StudyConfig.from_json(json.loads(json.dumps(config.to_json())))
    assert again == config
    assert again.ppo_settings["gamma"] == 0.99
    assert again.ppo_settings["n_steps"] == PPO_SETTINGS["n_steps"]


def _record(variant, kind, delay, seed, mean, age=None, dropped=None):
    return {
        "variant": variant,
        "kind": kind,
        "delay": delay,
        "seed": seed,
        "mean_return": mean,
        "mean_age_ticks": age,
        "dropped_fraction": dropped,
    }


def test_summary_and_table_give_each_variant_its_mean_spread_and_seeds():
    records = [
        _record("plain", "constant", 8, 0, 20.0),
        _record("plain", "constant", 8, 1, 40.0),
        _record("history", "constant", 8, 0, 500.0),
        _record("history", "constant", 8, 1, 480.0),
        _record("history", "random", "U(8,16)", 0, 300.0, age=9.5, dropped=0.5),
        _record("history", "random", "U(6,10)", 0, 200.0, age=7.0, dropped=0.25),
        _record("history", "random", "U(6,10)", 1, 100.0, age=8.0, dropped=0.35),
    ]
    summary = summarize(records)
    plain = next(s for s in summary if s["variant"] == "plain")
    assert plain["mean"] == 30.0 and plain["min"] == 20.0 and plain["max"] == 40.0 and plain["seeds"] == 2
    assert np.isclose(plain["std"], 10.0)
    # random models keep the order the study lists them in
    assert [s["delay"] for s in summary if s["kind"] == "random"] == ["U(8,16)", "U(6,10)"]
    references = {
        "constant": {"LQR (delay-unaware)": {"8": 46.0}},
        "random": {"LQR (delay-unaware)": {"U(6,10)": 52.0}, "expected": {"U(6,10)": 500.0}},
    }
    table = markdown_table(records, references)
    assert "| 8 | – | – | 30 (20–40) | 20, 40 | 490 (480–500) | 500, 480 | 46 | – |" in table
    assert "| U(6,10) | 7.50 | 0.30 | – | – | 150 (100–200) | 200, 100 | 52 | 500 |" in table
    assert "| U(8,16) | 9.50 | 0.50 | – | – | 300 (300–300) | 300 | – | – |" in table


def test_resume_keeps_records_of_the_same_configuration_only(tmp_path):
    config = StudyConfig(delays=(0,), random_delays=(), seeds=(0,), steps=10)
    path = str(tmp_path / "delay_effect.json")
    assert load_records(path, config) == []
    record = {
        **_record("plain", "constant", 0, 0, 9.0),
        **{"returns": [9.0] * config.eval_episodes, "history_length": 0, "include_alpha": False},
        **{"steps": 10, "train_s": 1.0, "train_return": 9.0, "curve": []},
    }
    write_json(path, {"config": config.to_json(), "records": [record]})
    assert load_records(path, config)[0]["mean_return"] == 9.0
    other = StudyConfig(delays=(0,), random_delays=(), seeds=(0,), steps=20)
    with pytest.raises(ValueError, match="another configuration"):
        load_records(path, other)
    assert [p.name for p in tmp_path.iterdir()] == ["delay_effect.json"]  # no temporary file left


def test_the_study_files_are_written_whole_and_readable_as_any_file_the_user_makes(tmp_path):
    import json
    import os
    import stat

    from remoteenv.latency.study.results import write_json

    path = tmp_path / "delay_effect.json"
    old = os.umask(0o022)
    try:
        write_json(str(path), {"records": [1, 2]})
    finally:
        os.umask(old)
    assert json.loads(path.read_text()) == {"records": [1, 2]}
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["delay_effect.json"]


def test_the_study_picks_the_policy_from_the_space_and_refuses_what_it_cannot_train():
    from gymnasium import spaces

    from remoteenv.latency.study.trainable_spaces import policy_for, space_problem

    image = spaces.Box(0, 255, (64, 64, 3), dtype=np.uint8)
    state = spaces.Box(-1, 1, (4,), dtype=np.float32)
    assert policy_for(state) == "MlpPolicy" and policy_for(image) == "CnnPolicy"
    assert policy_for(spaces.Dict({"state": state, "pixels": image})) == "MultiInputPolicy"
    box, discrete = spaces.Box(-1, 1, (1,)), spaces.Discrete(2)
    for ok in (state, image, spaces.Dict({"state": state, "pixels": image})):
        assert space_problem(ok, box) is None and space_problem(ok, discrete) is None
    assert "Box or Discrete action space" in space_problem(state, spaces.MultiDiscrete([2, 2]))
    assert "flatten them into Boxes" in space_problem(spaces.Dict({"a": spaces.Tuple([state])}), box)
    assert "rename that entry" in space_problem(spaces.Dict({"history": state}), box)
    assert "smaller than the 36x36" in space_problem(spaces.Box(0, 255, (24, 24, 3), dtype=np.uint8), box)
    assert "flat Dict" in space_problem(spaces.Tuple([state]), box)


def test_a_resumed_study_adds_its_wall_time_to_the_finished_segments_before_it(tmp_path):
    from remoteenv.latency.study.runner import _earlier_segments

    path = str(tmp_path / "delay_effect.json")
    assert _earlier_segments(path) == []
    write_json(path, {"wall_s": None, "records": []})  # cut off before its end: no wall time to add
    assert _earlier_segments(path) == []
    write_json(path, {"wall_s": 120.0, "records": []})  # written before segments were kept
    assert _earlier_segments(path) == [120.0]
    write_json(path, {"wall_s": 150.0, "segments": [120.0, 30.0], "records": []})
    assert _earlier_segments(path) == [120.0, 30.0]


def test_the_command_line_names_random_models_low_high():
    from remoteenv.cli.latency_study import random_models

    assert random_models("6:10, 0:16") == ["U(6,10)", "U(0,16)"]
    for bad in ("6-10", "10:6", "6:10:2", "a:b"):
        with pytest.raises(SystemExit):
            random_models(bad)
