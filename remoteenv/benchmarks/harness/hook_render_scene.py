"""Benchmark scene: the CartPole model whose observation is an image the scene
renders in its own hooks, the way env packages were written before the camera
API (no ``cameras=`` declared), so a world's tick costs a render that only a
measurement of its whole step sees.

Runs in the sim process (``python hook_render_scene.py ...``, started by a
:class:`remoteenv.RemoteVectorEnv`) or, for Gymnasium's vector envs, in the
agent process through :mod:`remoteenv.benchmarks.harness.in_process`
(``bench --pixels --pixels-render-in-hook``). Actions: ``Discrete(2)``, 0
pushes the cart left at full force, 1 right; reward 1 per tick; no
termination (a time limit ends episodes). The image: uint8
``(image_size, image_size, 3)`` from a fixed camera, without MSAA and shadows
like the camera CartPole's cheap path.
"""

from __future__ import annotations

import os
from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces

import remoteenv
from remoteenv.sim import BaseEnv, run_scene

MODEL = os.path.join(os.path.dirname(remoteenv.scene_path("cartpole")), "cartpole.xml")


class HookRenderCartPoleEnv(BaseEnv):
    """CartPole whose ``reset_model`` and ``post_step`` render its image observation themselves."""

    env_id = "HookRenderCartPole"

    def __init__(self, render_mode: str | None = None, image_size: int = 64) -> None:
        super().__init__(
            MODEL,
            frame_skip=2,
            observation_space=spaces.Box(0, 255, (image_size, image_size, 3), np.uint8),
            action_space=spaces.Discrete(2),
            render_mode=render_mode,
        )
        self.image_size = int(image_size)
        self.model.vis.quality.offsamples = 0
        self.model.vis.quality.shadowsize = 0
        self._eye: mujoco.Renderer | None = None

    def _image(self) -> np.ndarray:
        if self._eye is None:
            self._eye = mujoco.Renderer(self.model, self.image_size, self.image_size)
        self._eye.update_scene(self.data)
        return self._eye.render().copy()

    def reset_model(self, options: dict[str, Any] | None) -> tuple[np.ndarray, dict[str, Any]]:
        self.data.qpos[:] = self.np_random.uniform(-0.05, 0.05, size=self.model.nq)
        mujoco.mj_forward(self.model, self.data)
        return self._image(), {}

    def prepare_step(self, action: Any) -> None:
        self.data.ctrl[:] = 1.0 if int(action) else -1.0

    def post_step(self, action: Any) -> tuple[np.ndarray, float, bool, dict[str, Any]]:
        return self._image(), 1.0, False, {}

    def close(self) -> None:
        if self._eye is not None:
            self._eye.close()
            self._eye = None
        super().close()


if __name__ == "__main__":
    run_scene(HookRenderCartPoleEnv)
