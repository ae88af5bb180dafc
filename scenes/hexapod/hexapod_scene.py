"""Hexapod scene, sim side: a six-legged robot (gym-kraby's kind) learning to walk along +x.

Model (``hexapod.xml``): a 1.74 kg robot, a torso on a free joint and six legs
(order ``lf, lm, lr, rf, rm, rr``: left/right, front/middle/rear), each with
three hinge joints (order ``hip`` yaw, ``femur`` pitch, ``knee`` pitch), so
joint/actuator ``i`` is leg ``i // 3``, joint ``i % 3``. All joint angles are
0 in the standing pose. Joint ranges (rad): hip +-0.6, femur +-1.0, knee +-1.0.

Servos: 18 MuJoCo ``<position>`` actuators, kp 12 N m/rad, torque clamped to
+-1.5 N m (``forcerange``). Velocity limit: joint damping 0.3 N m s/rad =
stall torque / 5 rad/s, a DC servo's linear torque-speed line (integrated by
MuJoCo's implicitfast integrator: no per-substep Python), so a servo's own
torque cannot drive its joint faster than 5 rad/s. Outside forces can
(gravity, ground impacts, the torso's motion): measured, the tripod gait
stays under 5 rad/s, uniformly random actions reach about 7 rad/s at
moments. Armature 0.005 kg m^2 (the gearbox's reflected inertia). Set points
never leave the joint ranges: the action is clipped to [-1, 1] and scaled
into them.

Action: ``Box(-1, 1, (18,))`` float32, servo set points in actuator order:
``target_i = a_i * half_range_i`` (rad), so ``a = 0`` is the standing pose.
``None`` (no action yet, real-time mode) holds the standing pose.

Observation: ``Box(-inf, inf, (67,))`` float64:

====== ===== ==========================================================
index  size  content (units)
====== ===== ==========================================================
0      18    joint positions, actuator order (rad)
18     18    joint velocities (rad/s)
36     18    actuator torques, ``data.actuator_force`` (N m)
54     3     torso position x, y, z in the world (m)
57     4     torso orientation quaternion w, x, y, z (world from body)
61     3     torso linear velocity in the world frame (m/s)
64     3     torso angular velocity in the torso's own frame (rad/s)
====== ===== ==========================================================

(54:61 is the free joint's ``qpos``, 61:67 its ``qvel``, in MuJoCo's conventions.)

Reward per control tick: ``reward_forward + reward_ctrl`` where
``reward_forward`` = torso x displacement over the tick / dt (m/s) and
``reward_ctrl = -ctrl_cost_weight * sum(a^2)`` (default weight 0.01, so at
most 0.18 per tick). Step info: ``reward_forward``, ``reward_ctrl``,
``x_position`` (torso x, m); reset info: ``x_position``. All python floats.

Terminated when the torso flips: the world z component of its up axis < 0.
Truncation at 1000 steps is the agent side's (``remoteenv/Hexapod-v0``).

Time: physics timestep 0.005 s (implicitfast integrator), frame_skip 4, so a
control tick is dt = 0.02 s (50 Hz); 1000 steps are 20 s.

Reset: the standing pose (torso at 0.118 m, level, facing +x) with
``U(+-reset_noise_scale)`` added to every joint angle (rad) and joint
velocity (rad/s), default 0.05, drawn from ``self.np_random``.

Rendering: camera ``track`` follows the torso from behind and to its right.

Run by the launcher as ``python hexapod_scene.py --address ... --seed ...``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim import BaseEnv, BatchResult, run_scene, stacked

MODEL_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "hexapod.xml")

N_JOINTS = 18
OBS_SIZE = 3 * N_JOINTS + 3 + 4 + 6


class HexapodEnv(BaseEnv):
    env_id = "remoteenv/Hexapod-v0"
    metadata = {"render_modes": ["rgb_array", "human"]}
    default_camera = "track"
    # The batched hooks read and write state through stacked(): the worlds of a
    # process step in one mujoco.batch call.
    stacked_hooks = True

    def __init__(
        self,
        render_mode: str | None = None,
        ctrl_cost_weight: float = 0.01,
        reset_noise_scale: float = 0.05,
        width: int = 640,
        height: int = 480,
    ) -> None:
        super().__init__(
            MODEL_PATH,
            frame_skip=4,
            observation_space=spaces.Box(-np.inf, np.inf, shape=(OBS_SIZE,), dtype=np.float64),
            action_space=spaces.Box(-1.0, 1.0, shape=(N_JOINTS,), dtype=np.float32),
            render_mode=render_mode,
            width=width,
            height=height,
        )
        self.ctrl_cost_weight = float(ctrl_cost_weight)
        self.reset_noise_scale = float(reset_noise_scale)
        model = self.model
        if model.nu != N_JOINTS or model.nq != 7 + N_JOINTS:
            raise ValueError(f"{MODEL_PATH} must have a free joint and {N_JOINTS} actuated hinges")
        # Set point = centre + a * half width of each actuator's range (= its joint's range).
        low, high = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
        self._ctrl_centre = (low + high) / 2.0
        self._ctrl_half = (high - low) / 2.0
        self._torso = model.body("torso").id
        self._x_before = 0.0

    def reset_model(self, options: dict[str, Any] | None) -> tuple[np.ndarray, dict[str, Any]]:
        model, noise = self.model, self.reset_noise_scale
        qpos = model.qpos0.copy()
        qvel = np.zeros(model.nv)
        qpos[7:] += self.np_random.uniform(-noise, noise, size=N_JOINTS)
        qvel[6:] += self.np_random.uniform(-noise, noise, size=N_JOINTS)
        self.set_state(qpos, qvel)
        self.data.ctrl[:] = self._ctrl_centre
        self._x_before = float(self.data.qpos[0])
        return self._obs(), {"x_position": self._x_before}

    def prepare_step(self, action: np.ndarray | None) -> None:
        if action is None:
            self.data.ctrl[:] = self._ctrl_centre
        else:
            self.data.ctrl[:] = self._ctrl_centre + np.clip(action, -1.0, 1.0) * self._ctrl_half

    def post_step(self, action: np.ndarray | None) -> tuple[np.ndarray, float, bool, dict[str, Any]]:
        x = float(self.data.qpos[0])
        reward_forward = (x - self._x_before) / self.dt
        self._x_before = x
        ctrl = 0.0 if action is None else float(np.dot(action, action))
        reward_ctrl = -self.ctrl_cost_weight * ctrl
        # Row-major xmat: element 8 is the world z component of the torso's z axis.
        flipped = bool(self.data.xmat[self._torso, 8] < 0.0)
        info = {"reward_forward": reward_forward, "reward_ctrl": reward_ctrl, "x_position": x}
        return self._obs(), reward_forward + reward_ctrl, flipped, info

    @classmethod
    def prepare_steps(cls, envs: Sequence[BaseEnv], actions: np.ndarray) -> None:
        """:meth:`prepare_step` for all worlds at once (the same operations, stacked)."""
        bots: Sequence[HexapodEnv] = envs  # type: ignore[assignment]
        centre = np.array([bot._ctrl_centre for bot in bots])
        half = np.array([bot._ctrl_half for bot in bots])
        stacked(envs).set("ctrl", centre + np.clip(actions, -1.0, 1.0) * half)

    @classmethod
    def post_steps(cls, envs: Sequence[BaseEnv], actions: np.ndarray) -> BatchResult:
        """:meth:`post_step` for all worlds at once, with numpy over their stacked state."""
        bots: Sequence[HexapodEnv] = envs  # type: ignore[assignment]
        n = len(bots)
        state = stacked(envs)
        qpos, qvel = state.get("qpos"), state.get("qvel")
        x = qpos[:, 0].copy()
        x_before = np.fromiter((bot._x_before for bot in bots), np.float64, n)
        dt = np.fromiter((bot.dt for bot in bots), np.float64, n)
        reward_forward = (x - x_before) / dt
        for bot, now in zip(bots, x.tolist()):
            bot._x_before = now
        # A stacked matmul of float32 rows is the dot product np.dot takes (same rounding).
        ctrl = np.matmul(actions[:, None, :], actions[:, :, None])[:, 0, 0].astype(np.float64)
        weight = np.fromiter((bot.ctrl_cost_weight for bot in bots), np.float64, n)
        reward_ctrl = -weight * ctrl
        flipped = state.get("xmat")[:, bots[0]._torso, 8] < 0.0
        obs = np.concatenate((qpos[:, 7:], qvel[:, 6:], state.get("actuator_force"), qpos[:, :7], qvel[:, :6]), axis=1)
        info = {"reward_forward": reward_forward, "reward_ctrl": reward_ctrl, "x_position": x}
        return BatchResult(obs, reward_forward + reward_ctrl, flipped, info, python_scalars=frozenset(info))

    def _obs(self) -> np.ndarray:
        d = self.data
        return np.concatenate((d.qpos[7:], d.qvel[6:], d.actuator_force, d.qpos[:7], d.qvel[:6]))


def main(argv: list[str] | None = None) -> None:
    run_scene(HexapodEnv, argv, description=__doc__)


if __name__ == "__main__":
    main()
