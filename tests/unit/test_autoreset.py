"""Autoreset planning and reset arguments of the vector env: pure functions."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from remoteenv.agent.errors import StateError
from remoteenv.agent.session.reset_args import split_reset_mask, world_seeds
from remoteenv.agent.vector.autoreset import after_reset, after_step, plan_ops
from remoteenv.wire.protocol import OP_RESET, OP_STEP, OP_STEP_AUTORESET, OP_STEP_RESET

NEXT, SAME, DISABLED = AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED


def flags(*values: bool) -> np.ndarray:
    return np.array(values, dtype=np.bool_)


def counts(*values: int) -> np.ndarray:
    return np.array(values, dtype=np.int64)


def test_next_step_resets_the_worlds_that_ended():
    ops = plan_ops(NEXT, flags(False, True, False), counts(3, 5, 0), max_episode_steps=10)
    assert ops.tolist() == [OP_STEP, OP_RESET, OP_STEP]


def test_same_step_autoresets_and_resets_at_the_time_limit():
    ops = plan_ops(SAME, flags(False, False, False), counts(0, 8, 9), max_episode_steps=10)
    assert ops.tolist() == [OP_STEP_AUTORESET, OP_STEP_AUTORESET, OP_STEP_RESET]
    assert plan_ops(SAME, flags(False), counts(10_000), None).tolist() == [OP_STEP_AUTORESET]


def test_disabled_steps_only_and_refuses_ended_worlds():
    assert plan_ops(DISABLED, flags(False, False), counts(1, 2), 3).tolist() == [OP_STEP, OP_STEP]
    with pytest.raises(StateError, match=r"worlds \[1\] ended .*reset_mask"):
        plan_ops(DISABLED, flags(False, True), counts(1, 2), 3)


def test_after_step_counts_steps_and_applies_the_time_limit():
    ops = np.array([OP_STEP, OP_RESET, OP_STEP, OP_STEP])
    terminated = flags(False, False, True, False)
    truncated = flags(False, False, False, False)
    elapsed = counts(1, 7, 0, 2)
    trunc, new_elapsed, needs_reset = after_step(NEXT, ops, terminated, truncated, elapsed, max_episode_steps=3)
    assert new_elapsed.tolist() == [2, 0, 1, 3]
    assert trunc.tolist() == [False, False, False, True]  # world 3 reached the limit
    assert needs_reset.tolist() == [False, False, True, True]
    assert elapsed.tolist() == [1, 7, 0, 2] and not truncated.any()  # inputs untouched


def test_the_plan_where_every_world_steps_is_shared_read_only_and_booked_alike():
    plan = plan_ops(NEXT, flags(False, False, False), counts(3, 5, 0), max_episode_steps=6)
    assert plan.tolist() == [OP_STEP] * 3 and plan.dtype == np.int64
    assert plan_ops(NEXT, flags(False, False, False), counts(0, 0, 0), 6) is plan  # made once per size
    with pytest.raises(ValueError, match="read-only"):
        plan[0] = OP_RESET
    rng = np.random.default_rng(0)
    for _ in range(50):
        terminated, truncated = rng.random(3) < 0.2, rng.random(3) < 0.2
        elapsed = rng.integers(0, 8, 3)
        for limit in (6, None):
            shared = after_step(NEXT, plan, terminated, truncated, elapsed, limit)
            fresh = after_step(NEXT, plan.copy(), terminated, truncated, elapsed, limit)
            for a, b in zip(shared, fresh):
                np.testing.assert_array_equal(a, b)
                assert a.dtype == b.dtype


def test_after_step_in_same_step_mode_restarts_the_count_of_ended_worlds():
    ops = np.array([OP_STEP_AUTORESET, OP_STEP_RESET, OP_STEP_AUTORESET])
    trunc, elapsed, needs_reset = after_step(
        SAME, ops, flags(True, False, False), flags(False, False, False), counts(2, 4, 1), max_episode_steps=5
    )
    assert trunc.tolist() == [False, True, False]
    assert elapsed.tolist() == [0, 0, 2] and not needs_reset.any()


def test_after_step_without_a_limit_never_truncates():
    trunc, elapsed, _ = after_step(NEXT, np.array([OP_STEP]), flags(False), flags(False), counts(10**6), None)
    assert not trunc.any() and elapsed.tolist() == [10**6 + 1]


def test_after_reset_clears_only_the_masked_worlds():
    elapsed, needs_reset = counts(3, 4), flags(True, True)
    after_reset(flags(True, False), elapsed, needs_reset)
    assert elapsed.tolist() == [0, 4] and needs_reset.tolist() == [False, True]


def test_a_whole_episode_with_a_time_limit_in_each_mode():
    for mode in (NEXT, SAME):
        elapsed, needs_reset, seen = counts(0), flags(False), []
        for _ in range(5):
            ops = plan_ops(mode, needs_reset, elapsed, max_episode_steps=2)
            trunc, elapsed, needs_reset = after_step(mode, ops, flags(False), flags(False), elapsed, 2)
            seen.append((int(ops[0]), bool(trunc[0])))
        if mode == NEXT:
            assert seen == [(OP_STEP, False), (OP_STEP, True), (OP_RESET, False), (OP_STEP, False), (OP_STEP, True)]
        else:
            assert seen == [
                (OP_STEP_AUTORESET, False),
                (OP_STEP_RESET, True),
                (OP_STEP_AUTORESET, False),
                (OP_STEP_RESET, True),
                (OP_STEP_AUTORESET, False),
            ]


# ------------------------------------------------------------ reset arguments


def test_world_seeds():
    assert world_seeds(None, 3) == [None, None, None]
    assert world_seeds(5, 3) == [5, 6, 7]
    assert world_seeds(np.int64(2), 2) == [2, 3]
    assert world_seeds([1, None, np.int32(3)], 3) == [1, None, 3]
    with pytest.raises(ValueError, match="one per world: 3, got 2"):
        world_seeds([1, 2], 3)


def test_split_reset_mask():
    options, mask = split_reset_mask(None, 2, first_reset=True)
    assert options is None and mask.tolist() == [True, True]
    given = {"reset_mask": flags(False, True), "level": 3}
    options, mask = split_reset_mask(given, 2, first_reset=False)
    assert options == {"level": 3} and mask.tolist() == [False, True]
    assert "reset_mask" in given  # the caller's map is left alone
    with pytest.raises(TypeError, match="numpy bool array of shape \\(2,\\)"):
        split_reset_mask({"reset_mask": [True, False]}, 2, first_reset=False)
    with pytest.raises(ValueError, match="at least one"):
        split_reset_mask({"reset_mask": flags(False, False)}, 2, first_reset=False)
    with pytest.raises(StateError, match="first reset"):
        split_reset_mask({"reset_mask": flags(True, False)}, 2, first_reset=True)
