"""Test scene for the hardening tests: CartPole with costly behaviour on request.

``gil_items=n``: every step first runs ``sum(range(n))``, a loop in C that
holds the interpreter lock throughout (no other thread of the sim runs;
about 4 s for n = 10**8 on the test machine). ``info_bytes=n``: every step's
info holds a uint8 array of n bytes (a reply above the frame limit for n
large enough).
"""

import numpy as np

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import run_scene


class CostlyCartPole(CartPoleEnv):
    def __init__(self, gil_items=0, info_bytes=0, **kwargs):
        super().__init__(**kwargs)
        self.gil_items = int(gil_items)
        self.info_bytes = int(info_bytes)

    def post_step(self, action):
        if self.gil_items:
            sum(range(self.gil_items))
        obs, reward, terminated, info = super().post_step(action)
        if self.info_bytes:
            info = dict(info, blob=np.zeros(self.info_bytes, dtype=np.uint8))
        return obs, reward, terminated, info


if __name__ == "__main__":
    run_scene(CostlyCartPole)
