"""The renderers behind one world's cameras.

Runs in the sim process. A :class:`CameraRig` renders the images a world's
:class:`~remoteenv.sim.scene.cameras.CameraObservation` declares from the
world's ``MjData``: one ``mujoco.Renderer`` per image size (usually one per
world), made on the first image, closed with the world. Depth and
segmentation images come from the same renderer, switched to them for the
frame. With frame stacks the rig keeps each image's last frames.

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

from remoteenv.sim.scene.camera_geometry import camera_geometry
from remoteenv.sim.scene.cameras import Camera, CameraObservation, ImageEntry

#: ITU-R BT.601 luma weights (OpenCV's RGB2GRAY) in 1/256ths: 0.299, 0.587, 0.114.
_LUMA = np.array([77, 150, 29], dtype=np.uint16)


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
    """Renders one world's declared camera images (and stacks their frames).

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
        #: Each image's last frames, by key (frame stacks only; made at the first observation).
        self._stacks: dict[str, np.ndarray] = {}

    def _renderer(self, camera: Camera) -> mujoco.Renderer:
        key = (camera.width, camera.height)
        renderer = self._renderers.get(key)
        if renderer is None:
            renderer = cheap_renderer(self.model, camera.width, camera.height, self.observation.quality)
            self._renderers[key] = renderer
        return renderer

    def frame(self, data: mujoco.MjData, entry: ImageEntry, out: np.ndarray | None = None) -> np.ndarray:
        """One frame of ``entry``'s image of ``data`` now (``(H, W, C)``), into ``out`` if given."""
        camera = entry.camera
        renderer = self._renderer(camera)
        renderer.update_scene(data, camera=self._ids[camera.name])
        if out is None:
            out = np.empty(camera.image_shape(entry.kind), dtype=entry.dtype)
        if entry.kind == "rgb":
            return renderer.render(out=out)
        if entry.kind == "gray":
            rgb = renderer.render().astype(np.uint16)
            np.copyto(out[..., 0], (rgb @ _LUMA + 128) >> 8, casting="unsafe")
            return out
        if entry.kind == "depth":
            renderer.enable_depth_rendering()
            try:
                renderer.render(out=out[..., 0])  # metres along the view axis (MuJoCo converts)
            finally:
                renderer.disable_depth_rendering()
            return out
        renderer.enable_segmentation_rendering()
        try:
            ids = renderer.render()  # (H, W, 2): object id, object type; -1 where nothing is drawn
        finally:
            renderer.disable_segmentation_rendering()
        np.copyto(out[..., 0], np.where(ids[..., 1] == mujoco.mjtObj.mjOBJ_GEOM, ids[..., 0], -1))
        return out

    def frames(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        """One fresh frame of every image of ``data`` now, by key (nothing stacked)."""
        return {entry.key: self.frame(data, entry) for entry in self.observation.entries}

    def pixels(self, data: mujoco.MjData, out: Any = None, *, fresh: bool = False) -> Any:
        """The pixels of ``data`` now, as :meth:`CameraObservation.pixels_space`
        says: one image, or a dict of images by key; written into ``out`` (an
        array, or a dict of arrays, of that form) if given. With frame stacks
        each image holds its last frames; ``fresh`` (a reset) fills them all
        with this one."""
        entries = self.observation.entries
        if self.observation.single:
            return self._image(data, entries[0], out, fresh)
        return {e.key: self._image(data, e, None if out is None else out[e.key], fresh) for e in entries}

    def _image(self, data: mujoco.MjData, entry: ImageEntry, out: np.ndarray | None, fresh: bool) -> np.ndarray:
        k = self.observation.frame_stack
        if k == 1:
            return self.frame(data, entry, out)
        frame = self.frame(data, entry)
        stack = self._stacks.get(entry.key)
        if stack is None or fresh:
            stack = self._stacks[entry.key] = np.tile(frame, (1, 1, k))
        else:
            c = entry.channels
            stack[..., :-c] = stack[..., c:]  # numpy copies overlapping slices correctly
            stack[..., -c:] = frame
        if out is None:
            return stack.copy()
        np.copyto(out, stack)
        return out

    def geometry(self, data: mujoco.MjData) -> dict[str, dict[str, Any]]:
        """Each camera's intrinsics and extrinsics now, by camera name
        (:func:`~remoteenv.sim.scene.camera_geometry.camera_geometry`)."""
        return {
            c.name: camera_geometry(self.model, data, self._ids[c.name], c.width, c.height)
            for c in self.observation.cameras
        }

    def close(self) -> None:
        """Release the renderers (a later image makes new ones)."""
        renderers, self._renderers = self._renderers, {}
        for renderer in renderers.values():
            renderer.close()


def observe_worlds(envs: Sequence[Any], states: Any, out: np.ndarray | None = None) -> Any:
    """The observations of the worlds ``envs`` (one scene class, each with its
    :class:`CameraRig`) as they are now, from the state obs their batched hook
    returned (``states``: a stacked array or a list, one per world).

    One image alone (no state) comes as one ``(n, *shape)`` array, rendered
    straight into ``out`` when given (e.g. the shared region's block), else a
    new one; other declarations as a list of per-world observations."""
    observation = envs[0].camera_rig.observation
    n = len(envs)
    if observation.single and not observation.with_state:
        space = observation.pixels_space()
        images = out[:n] if out is not None else np.empty((n, *space.shape), dtype=space.dtype)
        for i, env in enumerate(envs):
            env.camera_rig.pixels(env.data, images[i])
        return images
    return [observation.compose(states[i], env.camera_rig.pixels(env.data)) for i, env in enumerate(envs)]


__all__ = ["CameraRig", "CameraSetupError", "check_cameras", "cheap_renderer", "observe_worlds"]
