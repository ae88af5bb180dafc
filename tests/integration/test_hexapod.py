"""remoteenv/Hexapod-v0 through gymnasium.make: checker, walking, rendering, the demo."""

from __future__ import annotations

import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

from remoteenv import controllers
from remoteenv.sim.scene import viewer

ENV_ID = "remoteenv/Hexapod-v0"


@pytest.fixture
def make():
    """gym.make that closes every env the test made."""
    envs = []

    def _make(**kwargs):
        env = gym.make(ENV_ID, **kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


def _not_about_infinite_bounds(caught) -> list[str]:
    # The observation space is unbounded, as Gymnasium's Ant and Reacher's are.
    return [str(w.message) for w in caught if "infinity" not in str(w.message)]


def test_registration_spaces_and_time_limit(make):
    env = make()
    assert env.spec.max_episode_steps == 1000
    assert env.observation_space == gym.spaces.Box(-np.inf, np.inf, (67,), np.float64)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (18,), np.float32)
    assert env.unwrapped.dt == pytest.approx(0.02) and env.metadata["render_fps"] == 50
    obs, info = env.reset(seed=0)
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):  # standing still, the episode runs to the limit
        obs, _, terminated, truncated, _ = env.step(np.zeros(18, dtype=np.float32))
        steps += 1
    assert (steps, terminated, truncated) == (1000, False, True)
    assert 0.1 < obs[56] < 0.12


def test_gymnasium_env_checker_passes_headless(make):
    """check_env without its render-mode sweep, which opens "human" and needs a
    display; rgb_array rendering is checked by Gymnasium's passive checker."""
    env = make(render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
        env_render_passive_checker(env.unwrapped)
    assert not _not_about_infinite_bounds(caught)


@pytest.mark.skipif(viewer.display_problem() is not None, reason="check_env opens render_mode='human'")
def test_gymnasium_env_checker_passes_with_every_render_mode(make):
    env = make()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert not _not_about_infinite_bounds(caught)


def test_tripod_gait_walks_forward(make):
    env = make()
    obs, info = env.reset(seed=0)
    x0, ret = info["x_position"], 0.0
    for step in range(200):
        obs, reward, terminated, truncated, info = env.step(controllers.hexapod_tripod(obs, step * env.unwrapped.dt))
        assert not (terminated or truncated)
        ret += reward
    assert info["x_position"] == obs[54]
    # About 1.2 m when measured; walking at all gives well over 0.5 m, standing or shuffling far less.
    assert info["x_position"] - x0 > 0.6
    assert abs(obs[55]) < 0.25  # kept its heading
    assert obs[56] > 0.09  # still up on its legs
    assert ret > 0.6 / 0.02 * 0.5  # forward reward dominates the control cost


def _robot_pixels(frame: np.ndarray) -> tuple[int, int]:
    """Counts of orange (legs) and blue (torso) pixels; floor and sky have neither."""
    rgb = frame.astype(np.int16)
    legs = int(np.count_nonzero(rgb[..., 0] - rgb[..., 2] > 80))
    torso = int(np.count_nonzero(rgb[..., 2] - rgb[..., 0] > 60))
    return legs, torso


def test_rgb_frame_shows_the_robot_while_it_walks(make):
    env = make(render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.shape == (480, 640, 3)
    assert first.std() > 10
    for step in range(100):
        obs, *_ = env.step(controllers.hexapod_tripod(obs, step * env.unwrapped.dt))
    later = env.render()
    assert obs[54] > 0.3  # it walked, and the tracking camera followed
    for frame in (first, later):
        legs, torso = _robot_pixels(frame)
        assert legs > 2000 and torso > 2000, (legs, torso)


def test_demo_walks_the_hexapod(capsys):
    from remoteenv.cli import main as cli_main

    assert cli_main(["demo", "hexapod", "--episodes", "1"]) == 0
    out = capsys.readouterr().out
    moved = re.search(r"steps 1000 \(truncated\).*x moved ([+-][0-9.]+) m", out)
    assert moved is not None, out
    assert float(moved.group(1)) > 3.0  # 6.2 m when measured
