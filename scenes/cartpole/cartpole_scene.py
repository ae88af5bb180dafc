"""CartPole scene, sim side: balance a pole on a cart (CartPole-v1's constants).

obs (float32): ``[x (m), x_dot (m/s), theta (rad), theta_dot (rad/s)]``,
theta = 0 upright. Actions: ``Discrete(2)`` (0 pushes with -10 N, 1 with
+10 N) or, with ``continuous=True``, ``Box(-1, 1, (1,))`` scaled to +-10 N.
Reward +1 per step; terminated when ``|x| > 2.4`` or ``|theta| > 12 deg``.
The agent side truncates after 500 steps. Control dt is 0.02 s (10 physics
substeps of 0.002 s).

Pixels: ``obs_mode="pixels"`` makes the observation the ``agent`` camera's
image (uint8 ``(image_size, image_size, 3)``), ``"state_pixels"`` a Dict
``{"state": <the 4 numbers>, "pixels": <the image>}``; rendered in the sim,
without multisampling and shadows unless ``camera_quality=True``
(docs/cameras.md). The default ``"state"`` is the 4 numbers alone.
``camera_kind`` (``"rgb"``, ``"depth"``, ``"segmentation"``, ``"rgbd"`` or a
list of kinds), ``cameras`` (``"agent"``, ``"side"`` or both) and
``frame_stack`` (the last k frames along the channel axis) choose the images;
several images make a flat Dict keyed ``"<camera>_<kind>"``.

Run by the launcher as ``python cartpole_scene.py --address ... --seed ...``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from remoteenv.sim import BaseEnv, BatchResult, Camera, camera_observation, run_scene, stacked

MODEL_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "cartpole.xml")

X_THRESHOLD = 2.4
THETA_THRESHOLD = 12 * 2 * math.pi / 360


class CartPoleEnv(BaseEnv):
    env_id = "remoteenv/CartPole-v0"
    metadata = {"render_modes": ["rgb_array", "human"]}
    default_camera = "side"
    # The batched hooks read and write state through stacked(): the worlds of a
    # process step in one mujoco.batch call.
    stacked_hooks = True

    def __init__(
        self,
        render_mode: str | None = None,
        continuous: bool = False,
        width: int = 600,
        height: int = 400,
        obs_mode: str = "state",
        image_size: int = 64,
        camera_quality: bool = False,
        camera_kind: str | Sequence[str] = "rgb",
        cameras: str | Sequence[str] = "agent",
        frame_stack: int = 1,
    ) -> None:
        if not isinstance(continuous, (bool, np.bool_)):
            raise ValueError(f"CartPoleEnv: continuous must be True or False, got {str(continuous)[:40]!r}")
        self.continuous = bool(continuous)
        kind = camera_kind if isinstance(camera_kind, str) else tuple(camera_kind)
        names = (cameras,) if isinstance(cameras, str) else tuple(cameras)
        observed = camera_observation(
            obs_mode,
            [Camera(name, width=image_size, height=image_size, kind=kind) for name in names],
            quality=camera_quality,
            frame_stack=frame_stack,
        )
        action_space: spaces.Space = (
            spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32) if self.continuous else spaces.Discrete(2)
        )
        high = np.array(
            [X_THRESHOLD * 2, np.finfo(np.float32).max, THETA_THRESHOLD * 2, np.finfo(np.float32).max],
            dtype=np.float32,
        )
        super().__init__(
            MODEL_PATH,
            frame_skip=10,
            observation_space=spaces.Box(-high, high, dtype=np.float32),
            action_space=action_space,
            render_mode=render_mode,
            width=width,
            height=height,
            cameras=observed,
        )
        self._terminated = False
        self._pole = self.model.body("pole").id

    @property
    def pole_mass(self) -> float:
        """Mass of the pole (kg, 0.1 by default). Set it per world for domain
        randomization; the pole's inertia scales with it."""
        return float(self.model.body_mass[self._pole])

    @pole_mass.setter
    def pole_mass(self, kg: float) -> None:
        if not kg > 0:
            raise ValueError(f"pole_mass must be > 0 kg, got {kg!r}")
        scale = float(kg) / self.model.body_mass[self._pole]
        self.model.body_mass[self._pole] = float(kg)
        self.model.body_inertia[self._pole] *= scale

    def reset_model(self, options: dict[str, Any] | None) -> tuple[np.ndarray, dict[str, Any]]:
        qpos, qvel = self._draw_start(options)
        self.set_state(qpos, qvel)
        self._terminated = False
        return self._obs(), {}

    def _draw_start(self, options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        """A start state ``(qpos, qvel)`` drawn from this world's RNG (``options``:
        ``low`` and ``high`` of the uniform draw)."""
        options = options or {}
        low, high = float(options.get("low", -0.05)), float(options.get("high", 0.05))
        x, x_dot, theta, theta_dot = self.np_random.uniform(low=low, high=high, size=(4,))
        return np.array([x, theta]), np.array([x_dot, theta_dot])

    @classmethod
    def reset_models(cls, envs: Sequence[BaseEnv], options: dict[str, Any] | None) -> tuple[np.ndarray, list]:
        """:meth:`reset_model` for all worlds at once: each world's draws, one stacked write and ``forward``."""
        carts: Sequence[CartPoleEnv] = envs  # type: ignore[assignment]
        n = len(carts)
        qpos, qvel = np.empty((n, 2)), np.empty((n, 2))
        for j, env in enumerate(carts):
            qpos[j], qvel[j] = env._draw_start(options)
            env._terminated = False
        worlds = stacked(envs)
        worlds.set("qpos", qpos)
        worlds.set("qvel", qvel)
        worlds.forward()
        return _stacked_obs(worlds.get("qpos"), worlds.get("qvel")), [{} for _ in range(n)]

    def force_fraction(self, action: Any) -> float:
        """Cart force as a fraction of 10 N for ``action`` (None: no force)."""
        if action is None:
            return 0.0
        if self.continuous:
            return float(np.clip(action[0], -1.0, 1.0))
        return 1.0 if int(action) == 1 else -1.0

    def prepare_step(self, action: Any) -> None:
        self.data.ctrl[0] = self.force_fraction(action)

    def post_step(self, action: Any) -> tuple[np.ndarray, float, bool, dict[str, Any]]:
        obs = self._obs()
        x, theta = float(obs[0]), float(obs[2])
        already = self._terminated
        self._terminated = already or abs(x) > X_THRESHOLD or abs(theta) > THETA_THRESHOLD
        # As in CartPole-v1: +1 per step including the terminating one, 0 after it.
        return obs, 0.0 if already else 1.0, self._terminated, {}

    @classmethod
    def prepare_steps(cls, envs: Sequence[BaseEnv], actions: np.ndarray) -> None:
        carts: Sequence[CartPoleEnv] = envs  # type: ignore[assignment]
        if carts[0].continuous:
            fractions = np.clip(actions[:, 0], -1.0, 1.0).astype(np.float64)
        else:
            fractions = np.where(actions == 1, 1.0, -1.0)
        stacked(envs).set("ctrl", fractions[:, None])

    @classmethod
    def post_steps(cls, envs: Sequence[BaseEnv], actions: np.ndarray) -> BatchResult:
        """:meth:`post_step` for all worlds at once, with numpy over their stacked state."""
        carts: Sequence[CartPoleEnv] = envs  # type: ignore[assignment]
        worlds = stacked(envs)
        obs = _stacked_obs(worlds.get("qpos"), worlds.get("qvel"))
        wide = obs.astype(np.float64)  # post_step compares float(obs[i]) with the thresholds
        already = np.fromiter((env._terminated for env in carts), np.bool_, len(carts))
        terminated = already | (np.abs(wide[:, 0]) > X_THRESHOLD) | (np.abs(wide[:, 2]) > THETA_THRESHOLD)
        for env, ended in zip(carts, terminated.tolist()):
            env._terminated = ended
        reward = np.where(already, 0.0, 1.0)
        return BatchResult(obs, reward, terminated, {})

    def _obs(self) -> np.ndarray:
        d = self.data
        return np.array([d.qpos[0], d.qvel[0], d.qpos[1], d.qvel[1]], dtype=np.float32)


def _stacked_obs(qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """The observations ``(n, 4)`` of worlds with stacked ``qpos`` and ``qvel``, as :meth:`CartPoleEnv._obs` per world."""
    return np.stack((qpos[:, 0], qvel[:, 0], qpos[:, 1], qvel[:, 1]), axis=1).astype(np.float32)


def main(argv: list[str] | None = None) -> None:
    run_scene(CartPoleEnv, argv, description=__doc__)


if __name__ == "__main__":
    main()
