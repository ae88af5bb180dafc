"""The hexapod scene's env class in this process (no sim process): layout, actions, reward, limits."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

import remoteenv


def _load_scene_module():
    spec = importlib.util.spec_from_file_location("hexapod_scene", remoteenv.scene_path("hexapod"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


scene = _load_scene_module()


@pytest.fixture
def env():
    e = scene.HexapodEnv()
    yield e
    e.close()


def test_observation_layout_is_the_documented_one(env):
    obs, info = env.reset(seed=0)
    d = env.data
    assert obs.shape == (67,) and obs.dtype == np.float64 and env.observation_space.contains(obs)
    np.testing.assert_array_equal(obs[0:18], d.qpos[7:])
    np.testing.assert_array_equal(obs[18:36], d.qvel[6:])
    np.testing.assert_array_equal(obs[36:54], d.actuator_force)
    np.testing.assert_array_equal(obs[54:57], d.xpos[env.model.body("torso").id])
    np.testing.assert_array_equal(obs[57:61], d.qpos[3:7])
    np.testing.assert_array_equal(obs[61:67], d.qvel[:6])
    # Standing, level, facing +x.
    assert obs[56] == pytest.approx(0.118)
    np.testing.assert_allclose(obs[57:61], [1.0, 0.0, 0.0, 0.0])
    assert info == {"x_position": pytest.approx(0.0)}
    # Joint order in the observation is actuator order.
    np.testing.assert_array_equal(env.model.jnt_qposadr[env.model.actuator_trnid[:, 0]], np.arange(7, 25))


def test_reset_is_the_standing_pose_plus_bounded_noise_from_the_seed(env):
    first, _ = env.reset(seed=3)
    again, _ = env.reset(seed=3)
    other, _ = env.reset(seed=4)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    for obs in (first, other):
        assert 0.0 < np.abs(obs[0:18]).max() <= 0.05
        assert 0.0 < np.abs(obs[18:36]).max() <= 0.05
        np.testing.assert_array_equal(obs[61:67], 0.0)


def test_actions_map_onto_each_joints_range(env):
    env.reset(seed=0)
    joint_range = env.model.jnt_range[env.model.actuator_trnid[:, 0]]
    env.prepare_step(np.ones(18, dtype=np.float32))
    np.testing.assert_allclose(env.data.ctrl, joint_range[:, 1])
    env.prepare_step(-np.ones(18, dtype=np.float32))
    np.testing.assert_allclose(env.data.ctrl, joint_range[:, 0])
    half = np.full(18, 0.5, dtype=np.float32)
    env.prepare_step(half)
    np.testing.assert_allclose(env.data.ctrl, 0.5 * joint_range[:, 1])
    env.prepare_step(None)  # no action yet: hold the standing pose
    np.testing.assert_array_equal(env.data.ctrl, 0.0)
    assert joint_range[0, 1] == pytest.approx(0.6) and joint_range[1, 1] == pytest.approx(1.0)


def test_reward_is_forward_velocity_minus_control_cost(env):
    env.reset(seed=0)
    x_before = float(env.data.qpos[0])
    action = np.linspace(-1.0, 1.0, 18).astype(np.float32)
    obs, reward, terminated, info = env.step(action)
    forward = (float(env.data.qpos[0]) - x_before) / 0.02
    ctrl = -0.01 * float(np.sum(action.astype(np.float64) ** 2))
    assert env.dt == pytest.approx(0.02)
    assert info["reward_forward"] == pytest.approx(forward)
    assert info["reward_ctrl"] == pytest.approx(ctrl, rel=1e-6)
    assert info["x_position"] == obs[54]
    assert reward == pytest.approx(forward + ctrl)
    assert all(type(v) is float for v in info.values()) and terminated is False
    _, reward, _, info = env.step(None)
    assert info["reward_ctrl"] == 0.0


def _set_tilt(env, angle: float) -> None:
    """Tilt the torso by ``angle`` (rad) about the x axis, 0.5 m up."""
    qpos = env.model.qpos0.copy()
    qpos[2] = 0.5
    qpos[3:7] = [math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0]
    env.set_state(qpos, np.zeros(env.model.nv))


@pytest.mark.parametrize(("angle", "flipped"), [(0.0, False), (1.4, False), (1.7, True), (math.pi, True)])
def test_terminated_when_the_torso_turns_upside_down(env, angle, flipped):
    env.reset(seed=0)
    _set_tilt(env, angle)
    _, _, terminated, _ = env.post_step(None)
    assert terminated is flipped


def test_servo_torque_and_speed_limits(env):
    """Full-range bang-bang set points, robot in the air without gravity: the
    servos saturate at 1.5 N m, and their damping line caps joint speed near
    5 rad/s (the floating torso's reaction adds a little)."""
    env.model.opt.gravity[:] = 0.0
    env.reset(seed=0)
    _set_tilt(env, 0.0)
    top_speed = top_torque = 0.0
    for tick in range(100):
        env.prepare_step(np.full(18, 1.0 if (tick // 10) % 2 else -1.0, dtype=np.float32))
        for _ in range(env.frame_skip):
            env.substep()
            top_speed = max(top_speed, float(np.abs(env.data.qvel[6:]).max()))
            top_torque = max(top_torque, float(np.abs(env.data.actuator_force).max()))
    assert top_torque == pytest.approx(1.5)
    assert 4.0 < top_speed < 5.0 * 1.05


def test_standing_still_with_zero_action(env):
    env.reset(seed=0)
    for _ in range(100):
        obs, _, terminated, _ = env.step(np.zeros(18, dtype=np.float32))
        assert not terminated
    assert 0.1 < obs[56] < 0.12
    assert abs(obs[54]) < 0.01 and abs(obs[55]) < 0.01
