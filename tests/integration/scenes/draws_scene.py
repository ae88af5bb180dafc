"""Test scene: CartPole that reports draws of the global RNGs (numpy's and
Python's), which a fresh interpreter seeds from the OS: no two sims may draw alike;
and how many objects the collector does not look at (those the zygote froze)."""

import gc
import random

import numpy as np

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import run_scene


class DrawsCartPole(CartPoleEnv):
    @property
    def global_draws(self) -> list[float]:
        return [float(np.random.random()), random.random()]

    @property
    def frozen_objects(self) -> int:
        return gc.get_freeze_count()


if __name__ == "__main__":
    run_scene(DrawsCartPole)
