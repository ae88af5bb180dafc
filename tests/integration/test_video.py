"""Gymnasium's RecordVideo and RecordEpisodeStatistics on remote envs, and ``demo --record``."""

from __future__ import annotations

import os
import sys

import gymnasium as gym
import numpy as np
import pytest

from remoteenv import controllers
from remoteenv.cli import main as cli_main

pytest.importorskip("moviepy")


def _is_mp4(path: str) -> bool:
    with open(path, "rb") as f:
        head = f.read(12)
    return len(head) == 12 and head[4:8] == b"ftyp"


def test_record_episode_statistics_counts_remote_rewards():
    env = gym.wrappers.RecordEpisodeStatistics(gym.make("remoteenv/CartPole-v0"))
    try:
        obs, _ = env.reset(seed=3)
        total, steps, done = 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(controllers.cartpole_discrete(obs))
            total += reward
            steps += 1
            done = terminated or truncated
        assert truncated and steps == 500  # the controller balances the pole to the time limit
        assert info["episode"]["r"] == pytest.approx(total)
        assert info["episode"]["l"] == steps
    finally:
        env.close()


def test_record_video_writes_one_mp4_per_episode(tmp_path):
    env = gym.make("remoteenv/Reacher-v0", render_mode="rgb_array", width=64, height=64)
    folder = tmp_path / "videos"
    env = gym.wrappers.RecordVideo(env, str(folder), episode_trigger=lambda e: True, name_prefix="reach")
    try:
        for episode in range(2):
            env.reset(seed=episode)
            done = False
            while not done:
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                done = terminated or truncated
        frame = env.render()
        assert isinstance(frame, np.ndarray) and frame.shape == (64, 64, 3) and frame.dtype == np.uint8
    finally:
        env.close()
    videos = sorted(os.listdir(folder))
    assert videos == ["reach-episode-0.mp4", "reach-episode-1.mp4"]
    assert all(_is_mp4(os.path.join(folder, v)) for v in videos)


def test_demo_record_writes_mp4(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli_main(["demo", "reacher", "--episodes", "1", "--record", str(out)]) == 0
    videos = os.listdir(out)
    assert videos == ["reacher-episode-0.mp4"]
    assert _is_mp4(os.path.join(out, videos[0]))
    assert "episode 0" in capsys.readouterr().out


def test_demo_record_without_moviepy_names_the_video_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "moviepy", None)  # "import moviepy" now fails
    with pytest.raises(SystemExit) as exit_:
        cli_main(["demo", "cartpole", "--episodes", "1", "--record", str(tmp_path / "out")])
    assert "pip install 'remoteenv[video]'" in str(exit_.value.code)
    assert not (tmp_path / "out").exists()


def test_record_video_of_the_agents_camera(tmp_path):
    """RenderObservation: render() is the observation's image (the newest frame of
    a stack, scaled up), so RecordVideo records what the agent saw, not the scene's
    600x400 side view."""
    from remoteenv.integrations.camera_video import RenderObservation

    env = gym.make("remoteenv/CartPole-v0", obs_mode="pixels", image_size=32, frame_stack=2)
    assert env.unwrapped.render_mode is None  # the scene renders nothing itself
    env = gym.wrappers.RecordVideo(
        RenderObservation(env, scale=2), str(tmp_path), episode_trigger=lambda e: True, name_prefix="agent"
    )
    try:
        obs, _ = env.reset(seed=0)
        for _ in range(6):
            obs, *_ = env.step(1)
            frame = env.render()
            assert frame.shape == (64, 64, 3) and frame.dtype == np.uint8
            np.testing.assert_array_equal(frame[::2, ::2], obs[..., -3:])  # the newest frame, each pixel 2x2
    finally:
        env.close()
    assert os.listdir(tmp_path) == ["agent-episode-0.mp4"]
    assert _is_mp4(os.path.join(tmp_path, "agent-episode-0.mp4"))


def test_render_observation_shows_depth_and_segmentation_of_a_dict():
    from remoteenv.integrations.camera_video import RenderObservation

    kwargs = {"obs_mode": "state_pixels", "image_size": 24, "camera_kind": ["rgb", "depth", "segmentation"]}
    for key, check in (
        (None, lambda frame, obs: np.array_equal(frame, obs["agent_rgb"])),  # the rgb image by default
        ("agent_depth", lambda frame, obs: (frame[..., 0] == frame[..., 2]).all() and frame.max() == 255),
        (
            "agent_segmentation",
            lambda frame, obs: ((obs["agent_segmentation"][..., 0] < 0) == (frame == 0).all(-1)).all(),
        ),
    ):
        env = RenderObservation(gym.make("remoteenv/CartPole-v0", **kwargs), key=key)
        try:
            obs, _ = env.reset(seed=0)
            frame = env.render()
            assert frame.shape == (24, 24, 3) and frame.dtype == np.uint8 and check(frame, obs), key
        finally:
            env.close()
