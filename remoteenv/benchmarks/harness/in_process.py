"""A shipped scene run in this process as a plain Gymnasium env: the same task
as the remote env, for Gymnasium's own vector envs to be measured against.

Benchmarks only. :class:`InProcessScene` builds the scene's env class (the
very code a sim runs: the same MJCF, hooks and camera renderer settings) here
and speaks Gymnasium's ``Env`` API; :func:`make_in_process` adds the
registered id's time limit. ``functools.partial(make_in_process, ...)`` is
what ``AsyncVectorEnv`` pickles to its workers.
"""

from __future__ import annotations

import importlib.util
import os
from typing import Any

import gymnasium as gym


def scene_class(scene: str) -> Any:
    """The env class of shipped scene ``scene`` (``"cartpole"``, ``"reacher"``) or of the
    scene script at path ``scene`` (a name ending in ``.py``), loaded from its script."""
    import remoteenv

    path = scene if scene.endswith(".py") else remoteenv.scene_path(scene)
    name = os.path.splitext(os.path.basename(path))[0]
    spec = importlib.util.spec_from_file_location(f"_in_process_{name}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    classes = [
        v
        for v in vars(module).values()
        if isinstance(v, type) and v.__module__ == module.__name__ and "Env" in v.__name__
    ]
    if len(classes) != 1:
        raise ValueError(f"scene {scene!r} ({path}) defines {len(classes)} env classes, expected one")
    return classes[0]


class InProcessScene(gym.Env):
    """Shipped scene ``scene``'s world in this process; ``kwargs`` go to its env class."""

    def __init__(self, scene: str, **kwargs: Any) -> None:
        self.world = scene_class(scene)(**kwargs)
        self.observation_space = self.world.observation_space
        self.action_space = self.world.action_space
        self.metadata = dict(self.world.metadata)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        return self.world.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, info = self.world.step(action)
        return obs, float(reward), bool(terminated), False, info

    def close(self) -> None:
        self.world.close()


def make_in_process(scene: str, max_episode_steps: int | None, **kwargs: Any) -> gym.Env:
    """:class:`InProcessScene` under ``TimeLimit(max_episode_steps)`` (None: no limit)."""
    env: gym.Env = InProcessScene(scene, **kwargs)
    return gym.wrappers.TimeLimit(env, max_episode_steps) if max_episode_steps else env


__all__ = ["InProcessScene", "make_in_process", "scene_class"]
