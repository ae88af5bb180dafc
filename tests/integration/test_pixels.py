"""The camera CartPole: pixel and Dict observations rendered in the sim, through
gym.make and the vector env, checked by Gymnasium's and SB3's env checkers and
against MuJoCo's own render of the same model in this process."""

from __future__ import annotations

import importlib.util
import os
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import remoteenv

ENV_ID = "remoteenv/CartPole-v0"
MODEL = os.path.join(os.path.dirname(remoteenv.scene_path("cartpole")), "cartpole.xml")


def _scene_class():
    spec = importlib.util.spec_from_file_location("cartpole_scene_pixels", remoteenv.scene_path("cartpole"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.CartPoleEnv


class _Reference:
    """The same task in this process: the scene's world stepped here, its
    images rendered by a plain ``mujoco.Renderer`` on the same MJCF with the
    cheap settings (no MSAA, no shadows)."""

    def __init__(self, size: int) -> None:
        self.world = _scene_class()()  # state observations: the pixels come from MuJoCo alone
        model = mujoco.MjModel.from_xml_path(MODEL)
        model.vis.quality.offsamples = 0
        model.vis.quality.shadowsize = 0
        self.renderer = mujoco.Renderer(model, height=size, width=size)

    def image(self) -> np.ndarray:
        self.renderer.update_scene(self.world.data, camera="agent")
        return self.renderer.render().copy()

    def close(self) -> None:
        self.renderer.close()
        self.world.close()


@pytest.mark.parametrize("obs_mode", ["pixels", "state_pixels"])
def test_gymnasium_and_sb3_checkers_pass(obs_mode):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(ENV_ID, obs_mode=obs_mode, image_size=48)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # any checker warning fails the test
            check_env(env.unwrapped, skip_render_check=True)
            sb3_checker.check_env(env, warn=True, skip_render_check=True)
        assert env.spec is not None and env.spec.max_episode_steps == 500  # the registration, unchanged
    finally:
        env.close()


@pytest.mark.parametrize("obs_mode", ["pixels", "state_pixels"])
def test_pixels_match_mujocos_render_of_the_same_state(obs_mode):
    size = 40
    env = gym.make(ENV_ID, obs_mode=obs_mode, image_size=size)
    reference = _Reference(size)
    try:
        obs, _ = env.reset(seed=3)
        state, _ = reference.world.reset(seed=3)
        for t in range(30):
            image = obs if obs_mode == "pixels" else obs["pixels"]
            assert image.dtype == np.uint8 and image.shape == (size, size, 3)
            np.testing.assert_array_equal(image, reference.image(), err_msg=f"tick {t}")
            if obs_mode == "state_pixels":
                np.testing.assert_array_equal(obs["state"], state)
            action = t % 3 % 2
            obs, _, terminated, _, _ = env.step(action)
            state, _, ended, _ = reference.world.step(action)
            assert terminated == ended
            if terminated:
                break
    finally:
        reference.close()
        env.close()


@pytest.mark.parametrize("obs_mode", ["pixels", "state_pixels"])
def test_vector_env_pixels_match_mujocos_render(obs_mode):
    """Three worlds in one sim process step in one mujoco.batch call (the
    cartpole's stacked hooks); their images still match, world by world."""
    size, n = 32, 3
    envs = gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        envs_per_process=n,
        obs_mode=obs_mode,
        image_size=size,
    )
    references = [_Reference(size) for _ in range(n)]
    try:
        assert envs.single_observation_space == gym.make(ENV_ID, obs_mode=obs_mode, image_size=size).observation_space
        obs, _ = envs.reset(seed=[10, 11, 12])
        for w, ref in enumerate(references):
            ref.world.reset(seed=10 + w)
        for t in range(12):
            images = obs if obs_mode == "pixels" else obs["pixels"]
            assert images.shape == (n, size, size, 3) and images.dtype == np.uint8
            for w, ref in enumerate(references):
                np.testing.assert_array_equal(images[w], ref.image(), err_msg=f"world {w}, tick {t}")
            actions = np.array([(t + w) % 2 for w in range(n)])
            obs, _, terminated, truncated, _ = envs.step(actions)
            for w, ref in enumerate(references):
                ref.world.step(int(actions[w]))
            assert not (terminated.any() or truncated.any())  # 12 ticks from a near-upright start
    finally:
        for ref in references:
            ref.close()
        envs.close()


def test_state_mode_is_the_default_and_unchanged():
    env = gym.make(ENV_ID)
    try:
        assert env.observation_space.shape == (4,) and env.observation_space.dtype == np.float32
    finally:
        env.close()


def test_reacher_takes_the_same_obs_modes():
    env = gym.make("remoteenv/Reacher-v0", obs_mode="state_pixels", image_size=32)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped, skip_render_check=True)
        # Reacher's state space is unbounded, as Gymnasium's Reacher-v5's is.
        assert not [str(w.message) for w in caught if "infinity" not in str(w.message)]
        obs, _ = env.reset(seed=0)
        assert obs["pixels"].shape == (32, 32, 3) and obs["state"].shape == (10,)
    finally:
        env.close()


def test_demo_takes_env_kwargs_and_balances_on_the_dicts_state(capsys):
    from remoteenv.cli import main as cli_main

    kwargs = '{"obs_mode": "state_pixels", "image_size": 24}'
    assert cli_main(["demo", "cartpole", "--episodes", "1", "--max-steps", "60", "--env-kwargs", kwargs]) == 0
    out = capsys.readouterr().out
    assert "env kwargs {'obs_mode': 'state_pixels', 'image_size': 24}" in out
    assert "'pixels': Box(0, 255, (24, 24, 3), uint8)" in out
    assert "steps   60 (truncated)" in out  # the LQR balanced on obs["state"]


def test_demo_refuses_env_kwargs_that_are_not_a_map():
    from remoteenv.cli import main as cli_main

    with pytest.raises(SystemExit, match="--env-kwargs must be a JSON map"):
        cli_main(["demo", "cartpole", "--env-kwargs", "[1]"])


def test_the_default_layout_spreads_costly_worlds_over_more_processes():
    from remoteenv.agent.vector.vector_layout import COSTLY_WORLD_S, default_envs_per_process

    made = []
    try:
        for kwargs in ({}, {"obs_mode": "pixels", "image_size": 32}):
            made.append(gym.make_vec(ENV_ID, num_envs=8, vectorization_mode="vector_entry_point", **kwargs).unwrapped)
        state, pixels = made
        cost_state = state.world_cost_s
        cost_pixels = pixels.world_cost_s
        assert 0 < cost_state < cost_pixels  # rendering a camera image costs more than CartPole's physics
        for env, cost in ((state, cost_state), (pixels, cost_pixels)):
            assert env.envs_per_process == min(8, default_envs_per_process(8, cost))
        if cost_pixels > COSTLY_WORLD_S:
            assert len(pixels.slices) > len(state.slices)
        obs, _ = pixels.reset(seed=0)
        assert obs.shape == (8, 32, 32, 3)
    finally:
        for env in made:
            env.close()


BAD_CAMERA_SCENE = """
import os
import numpy as np
from gymnasium import spaces
import remoteenv
from remoteenv.sim import BaseEnv, Camera, camera_observation, run_scene

MODEL = os.path.join(os.path.dirname(remoteenv.scene_path("cartpole")), "cartpole.xml")


class BadCamEnv(BaseEnv):
    def __init__(self, render_mode=None):
        pixels = camera_observation("pixels", Camera("top"))
        super().__init__(MODEL, 10, spaces.Box(-1, 1, (2,), np.float32), spaces.Discrete(2), cameras=pixels)

    def reset_model(self, options):
        return np.zeros(2, np.float32), {}


if __name__ == "__main__":
    run_scene(BadCamEnv)
"""


def test_a_camera_the_model_lacks_fails_the_start_naming_the_cameras_it_has(tmp_path):
    from remoteenv import OpenAIRemoteEnv
    from remoteenv.agent.errors import LaunchError

    script = tmp_path / "bad_camera_scene.py"
    script.write_text(BAD_CAMERA_SCENE)
    with pytest.raises(LaunchError, match=r"camera 'top' is not in the model; its cameras are \['side', 'agent'\]"):
        OpenAIRemoteEnv(str(script))


# ------------------------------------------------------------ frame stacks, modalities, geometry (issue 36)


def test_frame_stacks_on_the_batched_path_follow_each_worlds_episodes():
    """frame_stack=3 through the vector env (one image alone: the shared-memory
    rows): each image holds the world's last three frames, oldest first, and a
    world that autoresets starts its stack again from its first frame."""
    n, size = 2, 24
    stacked = gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        envs_per_process=n,
        obs_mode="pixels",
        image_size=size,
        frame_stack=3,
        max_episode_steps=4,
    )
    single = gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        envs_per_process=n,
        obs_mode="pixels",
        image_size=size,
        max_episode_steps=4,
    )
    try:
        assert stacked.single_observation_space.shape == (size, size, 9)
        obs, _ = stacked.reset(seed=[3, 4])
        frame, _ = single.reset(seed=[3, 4])
        frames = [frame, frame, frame]  # after a reset: the first frame three times
        for t in range(7):
            np.testing.assert_array_equal(obs, np.concatenate(frames[-3:], axis=-1), err_msg=f"step {t}")
            actions = np.array([t % 2, (t + 1) % 2])
            obs, _, _, truncated, _ = stacked.step(actions)
            frame, _, _, truncated_single, _ = single.step(actions)
            assert (truncated == truncated_single).all()
            frames.append(frame)
            if t == 4:  # the step after the 4-step limit: NEXT_STEP autoreset of both worlds
                frames = [frame, frame, frame]
    finally:
        stacked.close()
        single.close()


def test_depth_segmentation_and_two_cameras_as_one_flat_dict_that_sb3_trains_on():
    sb3 = pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.env_checker import check_env

    from remoteenv.sb3 import make_sb3_vec_env

    two = {"obs_mode": "state_pixels", "image_size": 36, "cameras": ["agent", "side"]}
    env = gym.make(ENV_ID, **two)
    try:
        assert set(env.observation_space.spaces) == {"state", "agent_rgb", "side_rgb"}
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # two rgb cameras: SB3's checker has nothing to say
            check_env(env, warn=True, skip_render_check=True)
    finally:
        env.close()
    kwargs = {**two, "camera_kind": "rgbd"}
    env = gym.make(ENV_ID, **kwargs)
    try:
        space = env.observation_space
        assert set(space.spaces) == {"state", "agent_rgb", "agent_depth", "side_rgb", "side_depth"}
        assert space["agent_depth"] == gym.spaces.Box(0.0, np.inf, (36, 36, 1), np.float32)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env, warn=True, skip_render_check=True)
        # SB3 only notes that the float32 depth images are no uint8 images in [0, 255] (they go to the MLP)
        notes = [str(w.message) for w in caught]
        assert notes and all("_depth is an image but" in note for note in notes), notes
        obs, _ = env.reset(seed=0)
        assert space.contains(obs)
    finally:
        env.close()
    venv = make_sb3_vec_env(ENV_ID, num_envs=2, seed=0, **kwargs)
    try:
        model = sb3.PPO("MultiInputPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0)
        model.learn(32)  # tiny: that SB3 takes the flat Dict, not what it learns
        assert set(model.policy.features_extractor.extractors) == set(space.spaces)
    finally:
        venv.close()


def test_vec_normalize_on_state_pixels_normalises_the_state_alone():
    """SB3's VecNormalize turns every Dict entry into normalised floats unless told
    which: norm_obs_keys=["state"] keeps the images uint8 images."""
    vec_env = pytest.importorskip("stable_baselines3.common.vec_env")
    from remoteenv.sb3 import make_sb3_vec_env

    venv = vec_env.VecNormalize(
        make_sb3_vec_env(ENV_ID, num_envs=2, seed=0, obs_mode="state_pixels", image_size=24), norm_obs_keys=["state"]
    )
    try:
        obs = venv.reset()
        assert obs["pixels"].dtype == np.uint8 and obs["state"].dtype == np.float32
        assert venv.observation_space["pixels"].dtype == np.uint8
    finally:
        venv.close()


def test_each_worlds_camera_geometry_projects_the_cart_onto_its_pixels():
    """Per world: the agent reads K and cam2world with call("camera_geometry") and
    projects the cart (x from the state) and a point up the pole to the pixels
    where the segmentation shows those geoms."""
    size, n = 120, 2
    envs = gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="vector_entry_point",
        envs_per_process=n,
        obs_mode="state_pixels",
        image_size=size,
        camera_kind=("rgb", "segmentation"),
    )
    model = mujoco.MjModel.from_xml_path(MODEL)
    try:
        obs, _ = envs.reset(seed=0, options={"low": 0.1, "high": 0.1})
        for _ in range(3):
            obs, *_ = envs.step(np.array([1, 0]))
        geometry = envs.call("camera_geometry")
        assert len(geometry) == n
        for w in range(n):
            K, pose = geometry[w]["agent"]["intrinsics"], geometry[w]["agent"]["cam2world"]
            x, theta = float(obs["state"][w, 0]), float(obs["state"][w, 2])
            for geom, point in (
                ("cart", (x, -0.12, 0.0)),
                ("pole", (x + 0.7 * np.sin(theta), 0.0, 0.7 * np.cos(theta))),
            ):
                camera = np.linalg.inv(pose) @ np.array([*point, 1.0])
                u, v = (K @ camera[:3])[:2] / camera[2]
                assert obs["agent_segmentation"][w, int(v), int(u), 0] == model.geom(geom).id, (w, geom)
        assert not np.allclose(obs["state"][0, 0], obs["state"][1, 0])  # two worlds, two cart positions
    finally:
        envs.close()
