"""Cameras a scene declares, and the observation spaces they give.

Runs in the sim process. A scene that observes through cameras declares them
(:class:`Camera`: an MJCF camera's name, the image size, what it renders:
rgb, depth, segmentation, or several of them) and how the images make its
observation (:class:`CameraObservation`): the image alone (a ``Box``), or
beside the scene's state in a flat ``Dict``. The spaces follow from the
declaration, so the handshake carries them like any other space. The
renderers that fill them are :mod:`remoteenv.sim.scene.camera_rig`'s.

Every image has a channel axis, channel-last (what Stable-Baselines3,
Gymnasium's image wrappers and RLlib's CNN read):

- ``"rgb"``: uint8 ``(H, W, 3)`` in ``Box(0, 255)``;
- ``"gray"``: uint8 ``(H, W, 1)``, the rgb image's luma (ITU-R BT.601
  weights, as OpenCV's ``RGB2GRAY``), in ``Box(0, 255)``;
- ``"depth"``: float32 ``(H, W, 1)``, metres from the camera's plane along its
  view axis (MuJoCo's ``Renderer`` depth), in ``Box(0, inf)``;
- ``"segmentation"``: int32 ``(H, W, 1)``, the id of the model geom drawn at
  each pixel (``-1``: nothing, the sky), in ``Box(-1, ngeom - 1)``.

``kind="rgbd"`` is shorthand for ``("rgb", "depth")``. With ``frame_stack=k``
each image holds the frames of the last ``k`` control ticks along its channel
axis, oldest first (``(H, W, 3k)`` for rgb; after a reset, the first frame
``k`` times), as SB3's ``VecFrameStack`` stacks channel-last images.

Keys: one image alone is the observation (``"pixels"`` beside ``"state"``,
Gymnasium's ``AddRenderObservation`` keys); several images (several cameras,
or several kinds) are a flat ``Dict`` keyed ``"<camera>_<kind>"``
(``"agent_rgb"``, ``"agent_depth"``), with ``"state"`` beside them when the
state is observed too. Never a nested ``Dict``: SB3's ``MultiInputPolicy``
refuses those.

:func:`camera_observation` turns the usual ``obs_mode`` argument of a scene
(``"state"``, ``"pixels"``, ``"state_pixels"``) into a declaration.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

#: What a camera renders, one image each (see the module docstring).
KINDS = ("rgb", "gray", "depth", "segmentation")
#: Shorthands for several kinds of one camera.
KIND_GROUPS = {"rgbd": ("rgb", "depth")}
#: The observation modes :func:`camera_observation` understands.
OBS_MODES = ("state", "pixels", "state_pixels")
#: Gymnasium's ``AddRenderObservation`` keys of a ``Dict`` observation.
STATE_KEY, PIXELS_KEY = "state", "pixels"
#: The largest image side a camera may declare (pixels).
MAX_SIDE = 4096
#: The most frames :attr:`CameraObservation.frame_stack` may stack.
MAX_FRAME_STACK = 64

_CHANNELS = {"rgb": 3, "gray": 1, "depth": 1, "segmentation": 1}
_DTYPES: dict[str, np.dtype] = {
    "rgb": np.dtype(np.uint8),
    "gray": np.dtype(np.uint8),
    "depth": np.dtype(np.float32),
    "segmentation": np.dtype(np.int32),
}


def _kinds(kind: Any) -> tuple[str, ...]:
    """``kind`` as a tuple of :data:`KINDS` (a group such as ``"rgbd"`` expanded), or ``()`` if invalid."""
    if isinstance(kind, str):
        return KIND_GROUPS.get(kind, (kind,) if kind in KINDS else ())
    if isinstance(kind, tuple) and kind and all(k in KINDS for k in kind) and len(set(kind)) == len(kind):
        return kind
    return ()


@dataclass(frozen=True)
class Camera:
    """One camera of a scene's observation.

    Attributes:
        name: the MJCF ``<camera name=...>`` the images are rendered from.
        width, height: the image size in pixels.
        kind: what it renders: one of :data:`KINDS`, ``"rgbd"``, or a tuple
            of several of :data:`KINDS` (one image each).
    """

    name: str
    width: int = 64
    height: int = 64
    kind: str | tuple[str, ...] = "rgb"

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Camera needs the name of an MJCF camera, got {self.name!r}")
        for side in ("width", "height"):
            value = getattr(self, side)
            if type(value) is not int or not 0 < value <= MAX_SIDE:
                raise ValueError(
                    f"Camera {self.name!r}: {side} must be an int in 1..{MAX_SIDE}, got {str(value)[:40]!r}"
                )
        if not _kinds(self.kind):
            choices = (*KINDS, *KIND_GROUPS)
            raise ValueError(
                f"Camera {self.name!r}: kind must be one of {choices} or a tuple of {KINDS}, got {str(self.kind)[:60]!r}"
            )

    @property
    def kinds(self) -> tuple[str, ...]:
        """The kinds this camera renders, one image each (``"rgbd"`` is ``("rgb", "depth")``)."""
        return _kinds(self.kind)

    def image_shape(self, kind: str, frames: int = 1) -> tuple[int, int, int]:
        """The shape of its ``kind`` image holding ``frames`` stacked frames."""
        return (self.height, self.width, _CHANNELS[kind] * frames)

    def image_space(self, kind: str, frames: int = 1, ngeom: int | None = None) -> spaces.Box:
        """The space of its ``kind`` image; segmentation ids are bounded by the model's ``ngeom`` when given."""
        shape = self.image_shape(kind, frames)
        if kind in ("rgb", "gray"):
            return spaces.Box(0, 255, shape, dtype=np.uint8)
        if kind == "depth":
            return spaces.Box(0.0, np.inf, shape, dtype=np.float32)
        high = np.iinfo(np.int32).max if ngeom is None else max(int(ngeom) - 1, -1)
        return spaces.Box(-1, high, shape, dtype=np.int32)

    @property
    def shape(self) -> tuple[int, int, int]:
        """A single-kind camera's image shape (one frame)."""
        return self.image_shape(self._only_kind())

    @property
    def dtype(self) -> np.dtype:
        """A single-kind camera's image dtype: uint8 rgb and gray, float32 depth, int32 segmentation."""
        return _DTYPES[self._only_kind()]

    @property
    def space(self) -> spaces.Box:
        """A single-kind camera's image space (one frame)."""
        return self.image_space(self._only_kind())

    def _only_kind(self) -> str:
        if len(self.kinds) != 1:
            raise ValueError(f"Camera {self.name!r} renders {self.kinds}: ask for one kind's image_shape/image_space")
        return self.kinds[0]


@dataclass(frozen=True)
class ImageEntry:
    """One image of an observation: its key, the camera and the kind it renders."""

    key: str
    camera: Camera
    kind: str

    @property
    def channels(self) -> int:
        """Channels of one frame: 3 (rgb) or 1."""
        return _CHANNELS[self.kind]

    @property
    def dtype(self) -> np.dtype:
        return _DTYPES[self.kind]


@dataclass(frozen=True)
class CameraObservation:
    """How a scene's cameras make its observation.

    Attributes:
        cameras: the cameras, at least one; each renders one image per kind.
        with_state: False: the observation is the images alone; True: a
            ``Dict`` with the scene's state obs under ``"state"`` beside them.
        quality: False (the default): render cheaply, without multisampling
            and shadows, whatever the MJCF's ``<quality>`` says (under
            software OpenGL the default 4x MSAA and 4096² shadow map cost about
            50x as much per frame); True: render at the MJCF's own quality.
        frame_stack: frames each image holds, of the last control ticks,
            stacked along the channel axis (1: the current frame only).
    """

    cameras: tuple[Camera, ...]
    with_state: bool = False
    quality: bool = False
    frame_stack: int = 1

    def __post_init__(self) -> None:
        check_flag("with_state", self.with_state)
        check_flag("quality", self.quality)
        if not self.cameras or not all(isinstance(c, Camera) for c in self.cameras):
            raise ValueError(f"CameraObservation needs one or more Camera, got {self.cameras!r}")
        names = [c.name for c in self.cameras]
        if len(set(names)) != len(names):
            raise ValueError(f"CameraObservation: each camera once, got {names}")
        if type(self.frame_stack) is not int or not 1 <= self.frame_stack <= MAX_FRAME_STACK:
            raise ValueError(
                f"CameraObservation: frame_stack must be an int in 1..{MAX_FRAME_STACK}, got {self.frame_stack!r}"
            )

    @property
    def entries(self) -> tuple[ImageEntry, ...]:
        """The images, in declaration order: ``"pixels"`` if there is one, else ``"<camera>_<kind>"`` each."""
        pairs = [(camera, kind) for camera in self.cameras for kind in camera.kinds]
        if len(pairs) == 1:
            return (ImageEntry(PIXELS_KEY, *pairs[0]),)
        return tuple(ImageEntry(f"{camera.name}_{kind}", camera, kind) for camera, kind in pairs)

    @property
    def single(self) -> bool:
        """Whether the pixels are one image (an array) rather than a dict of them."""
        return len(self.entries) == 1

    def entry_space(self, entry: ImageEntry, ngeom: int | None = None) -> spaces.Box:
        """The space of one image, its stacked frames included."""
        return entry.camera.image_space(entry.kind, self.frame_stack, ngeom)

    def pixels_space(self, ngeom: int | None = None) -> spaces.Space:
        """The images' space: one image's ``Box``, or a flat ``Dict`` of them by key."""
        if self.single:
            return self.entry_space(self.entries[0], ngeom)
        return spaces.Dict({e.key: self.entry_space(e, ngeom) for e in self.entries})

    def space(self, state_space: spaces.Space, ngeom: int | None = None) -> spaces.Space:
        """The observation space for a scene whose state obs has ``state_space``
        (``ngeom``: the model's geom count, bounding segmentation ids)."""
        if not self.with_state:
            return self.pixels_space(ngeom)
        images = {e.key: self.entry_space(e, ngeom) for e in self.entries}
        return spaces.Dict({STATE_KEY: state_space, **images})

    def compose(self, state: Any, pixels: Any) -> Any:
        """The observation from the state obs and the pixels (one array, or a dict by key)."""
        if not self.with_state:
            return pixels
        if self.single:
            return {STATE_KEY: state, PIXELS_KEY: pixels}
        return {STATE_KEY: state, **pixels}


def check_flag(name: str, value: Any) -> None:
    """Refuse anything but a bool for the flag ``name`` (``"no"`` is no False)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {str(value)[:40]!r}")


def camera_observation(
    obs_mode: str, cameras: Camera | Sequence[Camera], *, quality: bool = False, frame_stack: int = 1
) -> CameraObservation | None:
    """The declaration for a scene's ``obs_mode``: ``"state"`` None (no camera),
    ``"pixels"`` the images alone, ``"state_pixels"`` a Dict of state and images.
    ``frame_stack`` (images only) stacks each image's last frames."""
    if not isinstance(obs_mode, str) or obs_mode not in OBS_MODES:
        raise ValueError(f"obs_mode must be one of {OBS_MODES}, got {str(obs_mode)[:40]!r}")
    check_flag("camera quality", quality)
    if obs_mode == "state":
        if frame_stack != 1:
            raise ValueError(
                f"frame_stack={frame_stack!r} stacks camera images: it needs obs_mode 'pixels' or 'state_pixels'"
            )
        return None
    chosen = (cameras,) if isinstance(cameras, Camera) else tuple(cameras)
    return CameraObservation(chosen, with_state=obs_mode == "state_pixels", quality=quality, frame_stack=frame_stack)


__all__ = [
    "KINDS",
    "KIND_GROUPS",
    "OBS_MODES",
    "PIXELS_KEY",
    "STATE_KEY",
    "Camera",
    "CameraObservation",
    "ImageEntry",
    "camera_observation",
]
