"""The SB3 PPO benchmark (``bench --sb3``) on a tiny step count: every contender
trains, the times add up, and the ratios come from the measured figures.
Nothing here bounds a wall-clock time."""

from __future__ import annotations

import statistics

import pytest

pytest.importorskip("stable_baselines3")

from remoteenv.benchmarks import sb3_ppo

STEPS, ROUNDS = 512, 2


@pytest.fixture(scope="module")
def result():
    lines: list[str] = []
    out = sb3_ppo.measure(STEPS, ROUNDS, seed=0, log=lines.append)
    assert len(lines) == 2 * ROUNDS * len(sb3_ppo.CONTENDERS)  # a start and an end line per run
    return out


def test_every_contender_trains_in_every_round(result):
    runs = result["runs"]
    assert [(r["round"], r["contender"]) for r in runs] == [
        (k, name) for k in range(1, ROUNDS + 1) for name in sb3_ppo.CONTENDERS
    ]
    for run in runs:
        assert run["timesteps"] >= STEPS
        assert run["rollout_steps_per_s"] > 0 and run["cpu_s"] > 0
        assert run["episodes_in_mean"] > 0 and run["mean_return"] >= 1  # +1 a step
        assert run["torch_threads"] == result["torch_threads"]


def test_phases_add_up_to_at_most_the_total(result):
    for run in result["runs"]:
        assert 0 < run["env_step_s"] <= run["rollout_s"]
        assert 0 < run["train_s"]
        assert run["rollout_s"] + run["train_s"] <= run["total_s"]
        assert run["other_s"] == pytest.approx(run["total_s"] - run["rollout_s"] - run["train_s"])
        assert run["ppo_own_s"] == pytest.approx(run["total_s"] - run["env_step_s"])


def test_ratios_and_train_share_come_from_the_measured_medians(result):
    def median(name, key):
        return statistics.median(r[key] for r in result["runs"] if r["contender"] == name)

    ratios = {r["ratio"]: r for r in result["ratios"]}
    wall = ratios["remoteenv / SubprocVecEnv, learn() wall"]
    assert wall["target"] == sb3_ppo.TARGET
    assert wall["value"] == pytest.approx(median("remoteenv", "total_s") / median("SubprocVecEnv", "total_s"))
    rollout = ratios["remoteenv / SubprocVecEnv, rollout"]
    assert rollout["target"] is None
    assert rollout["value"] == pytest.approx(median("remoteenv", "rollout_s") / median("SubprocVecEnv", "rollout_s"))
    assert result["subproc_train_share"] == pytest.approx(
        median("SubprocVecEnv", "train_s") / median("SubprocVecEnv", "total_s")
    )
    least_ppo_own = min(median(name, "ppo_own_s") for name in sb3_ppo.CONTENDERS)
    assert result["ppo_floor_share"] == pytest.approx(least_ppo_own / median("SubprocVecEnv", "total_s"))


def test_the_table_states_the_verdict_and_the_torch_threads(result):
    table = sb3_ppo.format_table(result)
    assert f"torch {result['versions']['torch']} with {result['torch_threads']} threads" in table
    assert sb3_ppo.verdict(result) in table
    assert sum(line.startswith("SubprocVecEnv ") for line in table.splitlines()) == ROUNDS  # a row per run


@pytest.mark.parametrize(("share", "floor"), [(0.4, 0.45), (0.4, 0.55), (0.6, 0.7)])
def test_the_verdict_says_plainly_when_no_env_can_meet_the_target(share, floor):
    text = sb3_ppo.verdict({"subproc_train_share": share, "ppo_floor_share": floor})
    assert ("no env can meet" in text) == (floor > sb3_ppo.TARGET)
    assert ("train() alone" in text) == (share > sb3_ppo.TARGET)
