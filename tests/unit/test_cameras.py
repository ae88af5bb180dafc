"""Cameras in the sim: declarations, their spaces, the renderers, and observations
composed per world and per batch (remoteenv.sim.scene.cameras / camera_rig)."""

from __future__ import annotations

import importlib.util

import mujoco
import numpy as np
import pytest
from gymnasium import spaces

import remoteenv
from remoteenv.sim import Camera, CameraObservation, CameraSetupError, camera_observation
from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.camera_rig import CameraRig, cheap_renderer
from remoteenv.sim.stepping.batch_step import WorldsStepper


def _cartpole() -> type[BaseEnv]:
    spec = importlib.util.spec_from_file_location("cartpole_scene_cameras", remoteenv.scene_path("cartpole"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.CartPoleEnv


CartPole = _cartpole()
MODEL = CartPole.__init__.__globals__["MODEL_PATH"]


def _in_process_image(data: mujoco.MjData, size: int, *, cheap: bool = True) -> np.ndarray:
    """The agent camera's image of ``data`` rendered here with MuJoCo alone."""
    model = mujoco.MjModel.from_xml_path(MODEL)
    if cheap:
        model.vis.quality.offsamples = 0
        model.vis.quality.shadowsize = 0
    with mujoco.Renderer(model, height=size, width=size) as renderer:
        renderer.update_scene(data, camera="agent")
        return renderer.render().copy()


# ------------------------------------------------------------ declarations and spaces


@pytest.mark.parametrize(
    ("kwargs", "says"),
    [
        ({"name": ""}, "name of an MJCF camera"),
        ({"name": "a", "width": 0}, "width must be an int in 1..4096"),
        ({"name": "a", "height": 64.0}, "height must be an int"),
        ({"name": "a", "kind": "normals"}, "kind must be one of ('rgb', 'gray', 'depth', 'segmentation', 'rgbd')"),
        ({"name": "a", "kind": ("rgb", "rgb")}, "or a tuple of"),
    ],
)
def test_camera_refuses_bad_declarations(kwargs, says):
    with pytest.raises(ValueError, match=".*".join(map(__import__("re").escape, says.split("..")))):
        Camera(**kwargs)


def test_spaces_follow_the_declaration():
    state = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
    rgb, depth = Camera("a", 32, 24), Camera("b", 16, 8, kind="depth")
    assert rgb.space == spaces.Box(0, 255, (24, 32, 3), dtype=np.uint8)
    assert depth.space == spaces.Box(0.0, np.inf, (8, 16, 1), dtype=np.float32)  # a channel axis
    assert CameraObservation((rgb,)).space(state) == rgb.space
    both = CameraObservation((rgb,), with_state=True).space(state)
    assert isinstance(both, spaces.Dict) and set(both.spaces) == {"state", "pixels"}
    assert both["state"] == state and both["pixels"] == rgb.space
    with pytest.raises(ValueError, match="each camera once"):
        CameraObservation((rgb, rgb))


def test_several_images_make_one_flat_dict():
    """Several cameras, or several kinds of one, are keyed <camera>_<kind> beside
    the state: never a nested Dict (SB3's MultiInputPolicy refuses those)."""
    state = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
    several = CameraObservation((Camera("a", 8, 8), Camera("b", 8, 8, kind="rgbd")), with_state=True)
    space = several.space(state, ngeom=5)
    assert set(space.spaces) == {"state", "a_rgb", "b_rgb", "b_depth"}
    assert not any(isinstance(s, spaces.Dict) for s in space.spaces.values())
    assert space["b_depth"] == spaces.Box(0.0, np.inf, (8, 8, 1), dtype=np.float32)
    ids = CameraObservation((Camera("a", 8, 8, kind="segmentation"),)).space(state, ngeom=5)
    assert ids == spaces.Box(-1, 4, (8, 8, 1), dtype=np.int32)  # geom ids, -1 for none
    assert CameraObservation((Camera("a", 8, 8, kind=("rgb", "segmentation")),)).pixels_space().keys() == {
        "a_rgb",
        "a_segmentation",
    }


def test_frame_stacks_widen_the_channel_axis():
    stacked = CameraObservation((Camera("a", 8, 6, kind="rgbd"),), frame_stack=4)
    assert stacked.pixels_space() == spaces.Dict(
        {
            "a_rgb": spaces.Box(0, 255, (6, 8, 12), dtype=np.uint8),
            "a_depth": spaces.Box(0.0, np.inf, (6, 8, 4), dtype=np.float32),
        }
    )
    with pytest.raises(ValueError, match="frame_stack must be an int in 1..64"):
        CameraObservation((Camera("a"),), frame_stack=0)
    with pytest.raises(ValueError, match="frame_stack=2 stacks camera images: it needs obs_mode 'pixels'"):
        camera_observation("state", Camera("a"), frame_stack=2)


def test_obs_modes():
    camera = Camera("a")
    assert camera_observation("state", camera) is None
    assert camera_observation("pixels", camera) == CameraObservation((camera,), with_state=False)
    assert camera_observation("state_pixels", [camera], quality=True) == CameraObservation(
        (camera,), with_state=True, quality=True
    )
    with pytest.raises(ValueError, match="obs_mode must be one of"):
        camera_observation("rgb", camera)


# ------------------------------------------------------------ the renderers


def test_unknown_camera_and_too_large_images_are_refused_with_the_fix():
    model = mujoco.MjModel.from_xml_path(MODEL)
    with pytest.raises(
        CameraSetupError, match=r"camera 'top' is not in the model; its cameras are \['side', 'agent'\]"
    ):
        CameraRig(model, CameraObservation((Camera("top"),)), "CartPoleEnv")
    with pytest.raises(CameraSetupError, match=r'offwidth="2000" offheight="8"'):
        CameraRig(model, CameraObservation((Camera("agent", 2000, 8),)), "CartPoleEnv")


def test_cheap_renderer_puts_the_models_quality_back():
    model = mujoco.MjModel.from_xml_path(MODEL)
    before = int(model.vis.quality.offsamples), int(model.vis.quality.shadowsize)
    assert before != (0, 0)  # the MJCF keeps MuJoCo's default quality
    cheap_renderer(model, 8, 8, quality=False).close()
    assert (int(model.vis.quality.offsamples), int(model.vis.quality.shadowsize)) == before


@pytest.mark.parametrize("quality", [False, True])
def test_rig_images_match_mujocos_own_renderer(quality):
    model = mujoco.MjModel.from_xml_path(MODEL)
    data = mujoco.MjData(model)
    data.qpos[:] = [0.7, 0.15]
    mujoco.mj_forward(model, data)
    rig = CameraRig(model, CameraObservation((Camera("agent", 48, 48),), quality=quality), "CartPoleEnv")
    try:
        assert rig._renderers == {}  # made lazily
        image = rig.pixels(data)
        assert image.dtype == np.uint8 and image.shape == (48, 48, 3)
        np.testing.assert_array_equal(image, _in_process_image(data, 48, cheap=not quality))
        rig.close()
        np.testing.assert_array_equal(rig.pixels(data), image)  # a closed rig makes new renderers
    finally:
        rig.close()


def test_depth_segmentation_and_several_cameras():
    model = mujoco.MjModel.from_xml_path(MODEL)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    observation = CameraObservation((Camera("agent", 32, 32), Camera("side", 32, 32, kind=("depth", "segmentation"))))
    rig = CameraRig(model, observation, "CartPoleEnv")
    try:
        pixels = rig.pixels(data)
        assert set(pixels) == {"agent_rgb", "side_depth", "side_segmentation"}
        assert observation.pixels_space(model.ngeom).contains(pixels)
        depth, ids = pixels["side_depth"][..., 0], pixels["side_segmentation"][..., 0]
        # The side camera is 5 m from the track: down the middle column it sees the
        # cart's front face 4.88 m away (metres, as MuJoCo's Renderer converts its
        # depth buffer); the top row is sky: the far clipping plane, no geom.
        cart = model.geom("cart").id
        assert np.isclose(depth[:, 16], 4.88, atol=0.01).any()
        assert (ids[np.isclose(depth, 4.88, atol=0.01)] == cart).all()
        far = model.vis.map.zfar * model.stat.extent
        assert np.allclose(depth[0], far, rtol=1e-3) and (ids[0] == -1).all()
        # The rgb camera rendered after the others is plain rgb again.
        np.testing.assert_array_equal(rig.pixels(data)["agent_rgb"], pixels["agent_rgb"])
    finally:
        rig.close()


def test_a_frame_stack_holds_the_last_frames_oldest_first():
    model = mujoco.MjModel.from_xml_path(MODEL)
    data = mujoco.MjData(model)
    rig = CameraRig(model, CameraObservation((Camera("agent", 16, 16),), frame_stack=3), "CartPoleEnv")
    frames = []
    try:
        for t in range(5):
            data.qpos[:] = [0.3 * t, 0.0]
            mujoco.mj_forward(model, data)
            frames.append(rig.frames(data)["pixels"])
            stack = rig.pixels(data, fresh=t in (0, 3))
            assert stack.shape == (16, 16, 9)
            # after a reset (fresh) the first frame three times, then the newest last
            expected = [frames[max(i, 0 if t < 3 else 3)] for i in range(t - 2, t + 1)]
            np.testing.assert_array_equal(stack, np.concatenate(expected, axis=-1), err_msg=f"tick {t}")
        assert not np.array_equal(frames[0], frames[1])  # the cart moved: the frames differ
    finally:
        rig.close()


def test_camera_geometry_is_the_projection_the_renderer_draws():
    """K and cam2world map a world point to the pixel where the camera draws it:
    the cart's centre lands on the cart's geom, at the depth of its front face."""
    model = mujoco.MjModel.from_xml_path(MODEL)
    data = mujoco.MjData(model)
    data.qpos[:] = [0.9, 0.4]  # cart right of centre, pole tilted to +x
    mujoco.mj_forward(model, data)
    size = 120
    rig = CameraRig(model, CameraObservation((Camera("agent", size, size, kind=("depth", "segmentation")),)), "x")
    try:
        geometry = rig.geometry(data)["agent"]
        K, pose = geometry["intrinsics"], geometry["cam2world"]
        assert K.shape == (3, 3) and pose.shape == (4, 4) and (geometry["width"], geometry["height"]) == (size, size)
        pixels = rig.pixels(data)
        for geom, point, depth in (
            ("cart", [0.9, -0.12, 0.0], 6.38),  # the middle of the cart's front face
            ("pole", [0.9 + 0.8 * np.sin(0.4), 0.0, 0.8 * np.cos(0.4)], 6.455),  # 0.8 m up the pole
        ):
            camera_point = np.linalg.inv(pose) @ np.array([*point, 1.0])
            u, v = (K @ camera_point[:3])[:2] / camera_point[2]
            row, col = int(v), int(u)
            assert pixels["agent_segmentation"][row, col, 0] == model.geom(geom).id, geom
            assert pixels["agent_depth"][row, col, 0] == pytest.approx(depth, abs=0.02), geom
    finally:
        rig.close()


# ------------------------------------------------------------ observations of a scene


@pytest.mark.parametrize("obs_mode", ["pixels", "state_pixels"])
def test_batched_step_gives_the_per_world_observations(obs_mode):
    """Worlds stepped together (mujoco.batch, stacked hooks) observe exactly what
    each world stepped alone observes."""
    alone = [CartPole(obs_mode=obs_mode, image_size=32) for _ in range(3)]
    together = [CartPole(obs_mode=obs_mode, image_size=32) for _ in range(3)]
    stepper = WorldsStepper(together, threads=1)
    try:
        for i, (a, b) in enumerate(zip(alone, together)):
            first_a, _ = a.reset(seed=i)
            first_b, _ = b.reset(seed=i)
            assert a.observation_space.contains(first_a)
        actions = np.array([0, 1, 1])
        for _ in range(4):
            batch = stepper.step([0, 1, 2], actions)
            for w, env in enumerate(alone):
                obs, reward, terminated, _ = env.step(int(actions[w]))
                got = batch.world_obs(w)
                if obs_mode == "pixels":
                    assert isinstance(batch.obs, np.ndarray) and batch.obs.shape == (3, 32, 32, 3)
                    np.testing.assert_array_equal(got, obs)
                else:
                    np.testing.assert_array_equal(got["state"], obs["state"])
                    np.testing.assert_array_equal(got["pixels"], obs["pixels"])
                assert batch.reward[w] == reward and batch.terminated[w] == terminated
        # the pixels show the state: the same world's image matches MuJoCo's own render of it
        image = batch.world_obs(0) if obs_mode == "pixels" else batch.world_obs(0)["pixels"]
        np.testing.assert_array_equal(image, _in_process_image(together[0].data, 32))
    finally:
        stepper.close()
        for env in alone + together:
            env.close()


def test_state_mode_is_unchanged():
    env = CartPole()
    try:
        assert env.camera_rig is None and env.observation_space is env.state_space
        obs, _ = env.reset(seed=0)
        assert obs.shape == (4,) and obs.dtype == np.float32
    finally:
        env.close()


def test_batched_images_render_in_place_into_the_given_rows():
    """The shared region's rows: images go straight in, no copy after."""
    worlds = [CartPole(obs_mode="pixels", image_size=16) for _ in range(2)]
    stepper = WorldsStepper(worlds, threads=1)
    rows = np.zeros((4, 16, 16, 3), dtype=np.uint8)  # a region holds rows for every world of the process
    try:
        for i, env in enumerate(worlds):
            env.reset(seed=i)
        batch = stepper.step([0, 1], np.array([1, 0]), rows[:2])
        assert np.shares_memory(batch.obs, rows) and batch.obs.shape == (2, 16, 16, 3)
        assert rows[:2].any() and not rows[2:].any()
        np.testing.assert_array_equal(rows[0], _in_process_image(worlds[0].data, 16))
    finally:
        stepper.close()
        for env in worlds:
            env.close()


def test_sims_get_one_llvmpipe_thread_unless_the_user_chose(monkeypatch):
    from remoteenv.agent.launch.sim_command import launch_environment

    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    assert launch_environment(None)["LP_NUM_THREADS"] == "1"
    monkeypatch.setenv("LP_NUM_THREADS", "4")
    assert launch_environment(None)["LP_NUM_THREADS"] == "4"


# Issue 35, item 8: the shipped scenes took camera_quality="no" as True and
# image_size 64.7, "64" and True as 64 (they converted with bool() and int()).
@pytest.mark.parametrize("scene", ["cartpole", "reacher"])
@pytest.mark.parametrize(
    ("kwargs", "says"),
    [
        ({"camera_quality": "no"}, "camera quality must be True or False, got 'no'"),
        ({"camera_quality": 0}, "camera quality must be True or False"),
        ({"image_size": 64.7}, "width must be an int in 1..4096, got '64.7'"),
        ({"image_size": "64"}, "width must be an int in 1..4096, got '64'"),
        ({"image_size": True}, "width must be an int in 1..4096, got 'True'"),
        ({"image_size": float("nan")}, "width must be an int"),
        ({"obs_mode": "pixles"}, "obs_mode must be one of"),
    ],
)
def test_the_shipped_scenes_refuse_loose_camera_arguments(scene, kwargs, says):
    spec = importlib.util.spec_from_file_location(f"{scene}_scene_loose", remoteenv.scene_path(scene))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    cls = next(
        v for k, v in vars(module).items() if isinstance(v, type) and issubclass(v, BaseEnv) and v is not BaseEnv
    )
    with pytest.raises(ValueError, match=says.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.")):
        cls(**{"obs_mode": "pixels", **kwargs})


def test_cartpole_refuses_a_continuous_flag_that_is_no_bool():
    with pytest.raises(ValueError, match="continuous must be True or False"):
        CartPole(continuous=float("nan"))
    assert CartPole(continuous=np.bool_(True)).continuous is True
