"""The renderers behind one world's cameras.

Runs in the sim process. A :class:`CameraRig` renders the images a world's
:class:`~remoteenv.sim.scene.cameras.CameraObservation` declares from the
world's ``MjData``: one ``mujoco.Renderer`` per image size (usually one per
world), made on the first image, closed with the world. Depth images come
from the same renderer, switched to depth for them.

Render quality: unless the declaration asks for ``quality``, the renderer is
made with ``model.vis.quality.offsamples = 0`` (no multisampling) and
``shadowsize = 0`` (no shadow map), set on the model just before and put back
right after, so only the camera images are cheap: ``render_mode="rgb_array"``
frames keep the MJCF's quality.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from remoteenv.sim.scene.cameras import Camera, CameraObservation


class CameraSetupError(ValueError):
    """A declared camera does not fit the scene's model (unknown name, too large an image)."""


def check_cameras(model: mujoco.MjModel, observation: CameraObservation, scene: str) -> None:
    """Raise :class:`CameraSetupError` unless every camera names one of the
    model's cameras and fits its offscreen buffer (``<visual><global offwidth
    offheight>``), saying what to change."""
    names = [model.camera(i).name for i in range(model.ncam)]
    buffer = (int(model.vis.global_.offwidth), int(model.vis.global_.offheight))
    for camera in observation.cameras:
        if camera.name not in names:
            raise CameraSetupError(
                f"{scene}: camera {camera.name!r} is not in the model; its cameras are {names or 'none'} "
                '(add <camera name="..." pos="..." xyaxes="..."/> to the MJCF, or declare one of those)'
            )
        if camera.width > buffer[0] or camera.height > buffer[1]:
            raise CameraSetupError(
                f"{scene}: camera {camera.name!r} asks for {camera.width}x{camera.height} pixels, larger than the "
                f"model's offscreen buffer {buffer[0]}x{buffer[1]}; raise it in the MJCF with "
                f'<visual><global offwidth="{camera.width}" offheight="{camera.height}"/></visual>'
            )


def cheap_renderer(model: mujoco.MjModel, width: int, height: int, quality: bool) -> mujoco.Renderer:
    """A ``mujoco.Renderer`` for ``model``; unless ``quality``, made without
    multisampling and shadows (the model's ``vis.quality`` is put back after)."""
    if quality:
        return mujoco.Renderer(model, height=height, width=width)
    settings = model.vis.quality
    kept = int(settings.offsamples), int(settings.shadowsize)
    settings.offsamples, settings.shadowsize = 0, 0
    try:
        return mujoco.Renderer(model, height=height, width=width)
    finally:
        settings.offsamples, settings.shadowsize = kept


class CameraRig:
    """Renders one world's declared camera images.

    Args:
        model: the world's model (its cameras checked with :func:`check_cameras`).
        observation: the declaration.
        scene: the scene's class name, for messages.
    """

    def __init__(self, model: mujoco.MjModel, observation: CameraObservation, scene: str) -> None:
        check_cameras(model, observation, scene)
        self.model = model
        self.observation = observation
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._ids = {camera.name: model.camera(camera.name).id for camera in observation.cameras}

    def _renderer(self, camera: Camera) -> mujoco.Renderer:
        key = (camera.width, camera.height)
        renderer = self._renderers.get(key)
        if renderer is None:
            renderer = cheap_renderer(self.model, camera.width, camera.height, self.observation.quality)
            self._renderers[key] = renderer
        return renderer

    def image(self, data: mujoco.MjData, camera: Camera, out: np.ndarray | None = None) -> np.ndarray:
        """``camera``'s image of ``data`` now, into ``out`` if given (its shape and dtype)."""
        renderer = self._renderer(camera)
        renderer.update_scene(data, camera=self._ids[camera.name])
        if camera.kind == "depth":
            renderer.enable_depth_rendering()
            try:
                return renderer.render(out=out)
            finally:
                renderer.disable_depth_rendering()
        return renderer.render(out=out)

    def pixels(self, data: mujoco.MjData, out: Any = None) -> Any:
        """The pixels of ``data`` now, as :meth:`CameraObservation.pixels_space`
        says: one camera's image, or a dict of images by camera name; written
        into ``out`` (an array, or a dict of arrays, of that form) if given."""
        cameras = self.observation.cameras
        if len(cameras) == 1:
            return self.image(data, cameras[0], out)
        return {c.name: self.image(data, c, None if out is None else out[c.name]) for c in cameras}

    def close(self) -> None:
        """Release the renderers (a later image makes new ones)."""
        renderers, self._renderers = self._renderers, {}
        for renderer in renderers.values():
            renderer.close()


def observe_worlds(envs: Sequence[Any], states: Any, out: np.ndarray | None = None) -> Any:
    """The observations of the worlds ``envs`` (one scene class, each with its
    :class:`CameraRig`) as they are now, from the state obs their batched hook
    returned (``states``: a stacked array or a list, one per world).

    A single camera's images alone come as one ``(n, *shape)`` array, rendered
    straight into ``out`` when given (e.g. the shared region's block), else a
    new one; other declarations as a list of per-world observations."""
    observation = envs[0].camera_rig.observation
    n = len(envs)
    if len(observation.cameras) == 1 and not observation.with_state:
        camera = observation.cameras[0]
        images = out[:n] if out is not None else np.empty((n, *camera.shape), dtype=camera.dtype)
        for i, env in enumerate(envs):
            env.camera_rig.image(env.data, camera, images[i])
        return images
    return [observation.compose(states[i], env.camera_rig.pixels(env.data)) for i, env in enumerate(envs)]


__all__ = ["CameraRig", "CameraSetupError", "check_cameras", "cheap_renderer", "observe_worlds"]
