"""Observations are checked against the declared space where the scene produces them."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from remoteenv.sim.scene.obs_check import ObservationError, check_observation

BOX = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)


def test_a_fitting_observation_passes() -> None:
    check_observation(BOX, np.zeros(3, dtype=np.float32), scene="S", hook="post_step")
    check_observation(spaces.Discrete(4), np.int64(2), scene="S", hook="reset_model")
    check_observation(
        spaces.Dict({"a": BOX, "b": spaces.Discrete(2)}), {"a": np.zeros(3, np.float32), "b": 1}, scene="S", hook="h"
    )


@pytest.mark.parametrize(
    ("obs", "says"),
    [
        (np.zeros(3, dtype=np.float64), "dtype float64 and shape (3,), expected dtype float32 and shape (3,)"),
        (np.zeros(2, dtype=np.float32), "shape (2,), expected dtype float32 and shape (3,)"),
        ([0.0, 0.0, 0.0], "not a numpy array"),
    ],
)
def test_wrong_dtype_or_shape_names_scene_hook_space_and_value(obs: object, says: str) -> None:
    with pytest.raises(ObservationError) as err:
        check_observation(BOX, obs, scene="MyScene", hook="post_step")
    text = str(err.value)
    assert "MyScene.post_step" in text
    assert "Box(" in text
    assert says in text
    assert isinstance(err.value, TypeError)


def test_nested_spaces_name_the_failing_entry() -> None:
    space = spaces.Dict({"pos": BOX, "n": spaces.Discrete(3)})
    with pytest.raises(ObservationError, match=r"\['pos'\]"):
        check_observation(space, {"pos": np.zeros(3), "n": 1}, scene="S", hook="reset_model")
    with pytest.raises(ObservationError, match=r"\[1\]"):
        check_observation(
            spaces.Tuple((BOX, BOX)), (np.zeros(3, np.float32), np.zeros(4, np.float32)), scene="S", hook="h"
        )


def test_bounds_only_when_asked() -> None:
    outside = np.full(3, 5.0, dtype=np.float32)
    check_observation(BOX, outside, scene="S", hook="post_step")
    with pytest.raises(ObservationError, match="outside the space's bounds"):
        check_observation(BOX, outside, scene="S", hook="post_step", bounds=True)


def test_bad_input_is_not_echoed_in_full() -> None:
    with pytest.raises(ObservationError) as err:
        check_observation(spaces.Discrete(2), "x" * 100_000, scene="S", hook="h")
    assert len(str(err.value)) < 600
