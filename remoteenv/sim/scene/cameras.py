"""Cameras a scene declares, and the observation spaces they give.

Runs in the sim process. A scene that observes through cameras declares them
(:class:`Camera`: an MJCF camera's name, the image size, rgb or depth) and
how the images make its observation (:class:`CameraObservation`): the image
alone (a ``Box``) or beside the scene's state in a ``Dict`` with Gymnasium's
``AddRenderObservation`` keys, ``"state"`` and ``"pixels"``. The spaces follow
from the declaration, so the handshake carries them like any other space.
The renderers that fill them are :mod:`remoteenv.sim.scene.camera_rig`'s.

:func:`camera_observation` turns the usual ``obs_mode`` argument of a scene
(``"state"``, ``"pixels"``, ``"state_pixels"``) into a declaration.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

#: The image kinds a camera renders: rgb (uint8 ``(H, W, 3)``) and depth
#: (float32 ``(H, W)``, metres from the camera).
KINDS = ("rgb", "depth")
#: The observation modes :func:`camera_observation` understands.
OBS_MODES = ("state", "pixels", "state_pixels")
#: Gymnasium's ``AddRenderObservation`` keys of a ``Dict`` observation.
STATE_KEY, PIXELS_KEY = "state", "pixels"
#: The largest image side a camera may declare (pixels).
MAX_SIDE = 4096


@dataclass(frozen=True)
class Camera:
    """One camera of a scene's observation.

    Attributes:
        name: the MJCF ``<camera name=...>`` the image is rendered from.
        width, height: the image size in pixels.
        kind: ``"rgb"`` (uint8 ``(height, width, 3)``) or ``"depth"``
            (float32 ``(height, width)``, metres along the view axis).
    """

    name: str
    width: int = 64
    height: int = 64
    kind: str = "rgb"

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Camera needs the name of an MJCF camera, got {self.name!r}")
        for side in ("width", "height"):
            value = getattr(self, side)
            if type(value) is not int or not 0 < value <= MAX_SIDE:
                raise ValueError(
                    f"Camera {self.name!r}: {side} must be an int in 1..{MAX_SIDE}, got {str(value)[:40]!r}"
                )
        if self.kind not in KINDS:
            raise ValueError(f"Camera {self.name!r}: kind must be one of {KINDS}, got {self.kind!r}")

    @property
    def shape(self) -> tuple[int, ...]:
        """The image's shape: ``(height, width, 3)`` for rgb, ``(height, width)`` for depth."""
        return (self.height, self.width, 3) if self.kind == "rgb" else (self.height, self.width)

    @property
    def dtype(self) -> np.dtype:
        """The image's dtype: uint8 for rgb, float32 for depth."""
        return np.dtype(np.uint8) if self.kind == "rgb" else np.dtype(np.float32)

    @property
    def space(self) -> spaces.Box:
        """The image's space: ``Box(0, 255, shape, uint8)`` or ``Box(0, inf, shape, float32)``."""
        if self.kind == "rgb":
            return spaces.Box(0, 255, self.shape, dtype=np.uint8)
        return spaces.Box(0.0, np.inf, self.shape, dtype=np.float32)


@dataclass(frozen=True)
class CameraObservation:
    """How a scene's cameras make its observation.

    Attributes:
        cameras: the cameras, at least one. With one, the pixels are its
            image; with several, a ``Dict`` of images keyed by camera name.
        with_state: False: the observation is the pixels alone; True: a
            ``Dict`` ``{"state": <the scene's state obs>, "pixels": <the pixels>}``
            (Gymnasium's ``AddRenderObservation`` keys).
        quality: False (the default): render cheaply, without multisampling
            and shadows, whatever the MJCF's ``<quality>`` says (under
            software OpenGL the default 4x MSAA and 4096² shadow map cost about
            50x as much per frame); True: render at the MJCF's own quality.
    """

    cameras: tuple[Camera, ...]
    with_state: bool = False
    quality: bool = False

    def __post_init__(self) -> None:
        check_flag("with_state", self.with_state)
        check_flag("quality", self.quality)
        if not self.cameras or not all(isinstance(c, Camera) for c in self.cameras):
            raise ValueError(f"CameraObservation needs one or more Camera, got {self.cameras!r}")
        names = [c.name for c in self.cameras]
        if len(set(names)) != len(names):
            raise ValueError(f"CameraObservation: each camera once, got {names}")

    def pixels_space(self) -> spaces.Space:
        """The pixels' space: one camera's ``Box``, or a ``Dict`` by camera name."""
        if len(self.cameras) == 1:
            return self.cameras[0].space
        return spaces.Dict({c.name: c.space for c in self.cameras})

    def space(self, state_space: spaces.Space) -> spaces.Space:
        """The observation space for a scene whose state obs has ``state_space``."""
        if not self.with_state:
            return self.pixels_space()
        return spaces.Dict({STATE_KEY: state_space, PIXELS_KEY: self.pixels_space()})

    def compose(self, state: Any, pixels: Any) -> Any:
        """The observation from the state obs and the pixels (as :meth:`space` says)."""
        return {STATE_KEY: state, PIXELS_KEY: pixels} if self.with_state else pixels


def check_flag(name: str, value: Any) -> None:
    """Refuse anything but a bool for the flag ``name`` (``"no"`` is no False)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {str(value)[:40]!r}")


def camera_observation(
    obs_mode: str, cameras: Camera | Sequence[Camera], *, quality: bool = False
) -> CameraObservation | None:
    """The declaration for a scene's ``obs_mode``: ``"state"`` None (no camera),
    ``"pixels"`` the images alone, ``"state_pixels"`` a Dict of state and images."""
    if not isinstance(obs_mode, str) or obs_mode not in OBS_MODES:
        raise ValueError(f"obs_mode must be one of {OBS_MODES}, got {str(obs_mode)[:40]!r}")
    check_flag("camera quality", quality)
    if obs_mode == "state":
        return None
    chosen = (cameras,) if isinstance(cameras, Camera) else tuple(cameras)
    return CameraObservation(chosen, with_state=obs_mode == "state_pixels", quality=quality)


__all__ = [
    "KINDS",
    "OBS_MODES",
    "PIXELS_KEY",
    "STATE_KEY",
    "Camera",
    "CameraObservation",
    "camera_observation",
]
