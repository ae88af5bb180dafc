"""Video of what the agent sees: ``render()`` returns the observation's camera image.

Runs in the agent process, on any Gymnasium env whose observation is a
camera image or a flat Dict holding some. Gymnasium's ``RecordVideo``
records ``env.render()``, which on a remote scene is its ``render_mode``
frame (the scene's ``default_camera`` at ``width`` x ``height``, e.g.
CartPole's 600x400 side view), not the image the policy acted on.
:class:`RenderObservation` makes ``render()`` return the last observation's
image instead, so ``RecordVideo`` records exactly what the agent saw, at
the time it saw it (a real-time env included: nothing is rendered again)::

    env = gym.make("remoteenv/CartPole-v0", obs_mode="pixels")
    env = gym.wrappers.RecordVideo(RenderObservation(env, scale=4), "videos")

The frame is the newest of a frame stack, as uint8 ``H x W x 3``: rgb as
it is, gray repeated over the three channels, depth as inverse depth
(nearest point white, the far clipping plane nearly black), segmentation
ids in a fixed colour each (black where no geom is). ``scale`` repeats
each pixel ``scale`` times in both directions (a 64x64 image is small to
watch); the observation itself is untouched.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

#: Image kinds, by the key suffix the camera observations use (``"agent_depth"``).
KINDS = ("rgb", "gray", "depth", "segmentation")


def _kind_of(key: str | None, space: spaces.Box) -> str:
    """The image kind: from a ``"<camera>_<kind>"`` key, else from the dtype and channels."""
    if key is not None:
        for kind in KINDS:
            if key.endswith("_" + kind):
                return kind
    if space.dtype == np.uint8:
        return "rgb" if space.shape[-1] % 3 == 0 else "gray"
    return "depth" if np.issubdtype(space.dtype, np.floating) else "segmentation"


def _image_key(space: spaces.Space) -> str | None:
    """The Dict key of the image to show: ``"pixels"``, else the first rgb, else the first image."""
    if not isinstance(space, spaces.Dict):
        return None
    images = [k for k, s in space.spaces.items() if isinstance(s, spaces.Box) and len(s.shape) == 3]
    if not images:
        raise TypeError(f"RenderObservation: the Dict observation {space} holds no H x W x C image")
    if "pixels" in images:
        return "pixels"
    return next((k for k in images if k.endswith("_rgb")), images[0])


def to_rgb(image: np.ndarray, kind: str) -> np.ndarray:
    """The newest frame of a camera image (``H x W x C``, frames stacked on C) as uint8 ``H x W x 3``."""
    if kind == "rgb":
        return np.ascontiguousarray(image[..., -3:])
    frame = image[..., -1]
    if kind == "gray":
        grey = frame
    elif kind == "depth":
        depth = np.where(np.isfinite(frame) & (frame > 0), frame, np.inf)
        nearest = depth.min() if np.isfinite(depth.min()) else 1.0
        grey = np.round(255 * nearest / depth).astype(np.uint8)
    else:
        ids = frame.astype(np.int64)
        colours = np.stack([(ids * 97 + 61) % 256, (ids * 57 + 131) % 256, (ids * 29 + 197) % 256], axis=-1)
        return np.where(ids[..., None] >= 0, colours, 0).astype(np.uint8)
    return np.repeat(grey[..., None], 3, axis=-1).astype(np.uint8)


class RenderObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """``render()`` returns the last observation's camera image (see the module docstring).

    Args:
        env: an env whose observation is an ``H x W x C`` image Box or a flat
            Dict holding one.
        key: the Dict key of the image to show (default ``"pixels"``, else the
            first ``"*_rgb"`` key, else the first image).
        kind: ``"rgb"``, ``"gray"``, ``"depth"`` or ``"segmentation"``; by
            default read from the key's suffix, else from the dtype (a uint8
            image whose channels are a multiple of 3 is rgb: name ``"gray"``
            for three or six stacked gray frames).
        scale: each pixel repeated this many times in both directions.
    """

    def __init__(self, env: gym.Env, key: str | None = None, kind: str | None = None, scale: int = 1) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, key=key, kind=kind, scale=scale)
        gym.Wrapper.__init__(self, env)
        space = env.observation_space
        self.key = key if key is not None else _image_key(space)
        image_space = space.spaces[self.key] if isinstance(space, spaces.Dict) and self.key is not None else space
        if not isinstance(image_space, spaces.Box) or len(image_space.shape) != 3:
            raise TypeError(f"RenderObservation needs an H x W x C image observation, got {image_space}")
        if kind is not None and kind not in KINDS:
            raise ValueError(f"RenderObservation: kind must be one of {KINDS}, got {kind!r}")
        if type(scale) is not int or scale < 1:
            raise ValueError(f"RenderObservation: scale must be an int >= 1, got {scale!r}")
        self.kind = kind or _kind_of(self.key, image_space)
        self.scale = scale
        self._last: np.ndarray | None = None

    @property
    def render_mode(self) -> str:  # type: ignore[override]  # what RecordVideo asks for; the env's may be None
        return "rgb_array"

    def _keep(self, obs: Any) -> None:
        self._last = np.array(obs[self.key] if self.key is not None else obs)

    def reset(self, **kwargs: Any) -> Any:
        obs, info = self.env.reset(**kwargs)
        self._keep(obs)
        return obs, info

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._keep(obs)
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray:
        """The last observation's image as uint8 ``(H * scale, W * scale, 3)``."""
        if self._last is None:
            raise gym.error.ResetNeeded("RenderObservation: call reset() before render()")
        frame = to_rgb(self._last, self.kind)
        if self.scale > 1:
            frame = np.repeat(np.repeat(frame, self.scale, axis=0), self.scale, axis=1)
        return frame


__all__ = ["RenderObservation", "to_rgb"]
