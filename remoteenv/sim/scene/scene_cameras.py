"""The camera side of a scene env: its observation's images and its cameras' geometry.

Runs in the sim process. :class:`SceneCameras` is a mixin of
:class:`~remoteenv.sim.scene.base_env.BaseEnv`: it composes the hooks' state
obs with the images of the env's :class:`~remoteenv.sim.scene.camera_rig.CameraRig`
(``camera_rig``, None without cameras) and gives the observed cameras'
intrinsics and extrinsics.
"""

from __future__ import annotations

from typing import Any

import mujoco

from remoteenv.sim.scene.camera_rig import CameraRig


class SceneCameras:
    """:meth:`observe` and :meth:`camera_geometry` over ``self.camera_rig`` and ``self.data``."""

    camera_rig: CameraRig | None
    data: mujoco.MjData

    def observe(self, state: Any, *, fresh: bool = False) -> Any:
        """The observation now from the hooks' state obs: ``state``, or with cameras
        composed with their images (``fresh``: an episode's first, which fills frame stacks)."""
        rig = self.camera_rig
        return state if rig is None else rig.observation.compose(state, rig.pixels(self.data, fresh=fresh))

    def camera_geometry(self) -> dict[str, dict[str, Any]]:
        """Each observed camera's ``intrinsics`` (K, 3x3) and ``cam2world`` (4x4 pose,
        OpenCV axes), ``width`` and ``height`` now, by camera name
        (:mod:`remoteenv.sim.scene.camera_geometry`); an agent reads them with
        ``env.call("camera_geometry")``, one per world of a vector env."""
        if self.camera_rig is None:
            raise ValueError(f"{type(self).__name__} observes through no camera: no camera geometry to give")
        return self.camera_rig.geometry(self.data)


__all__ = ["SceneCameras"]
