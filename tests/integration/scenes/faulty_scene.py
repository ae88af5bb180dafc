"""Test scene: CartPole that fails on request (env kwargs chosen by the test).

``crash_after_steps=n``: the n-th step writes a line to stderr and ends the
process with ``os._exit(crash_code)``. ``hang_after_steps=n``: the n-th step
sleeps ``hang_seconds``. ``fail_on_start=True``: the constructor raises.
``unsendable_info=True``: every step's info holds an object msgpack cannot encode.
"""

import os
import sys
import time

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import run_scene


class FaultyCartPole(CartPoleEnv):
    def __init__(
        self,
        crash_after_steps=None,
        crash_code=3,
        hang_after_steps=None,
        hang_seconds=30.0,
        fail_on_start=False,
        unsendable_info=False,
        **kwargs,
    ):
        if fail_on_start:
            raise RuntimeError("faulty scene: refusing to start on purpose")
        super().__init__(**kwargs)
        self.crash_after_steps = crash_after_steps
        self.crash_code = crash_code
        self.hang_after_steps = hang_after_steps
        self.hang_seconds = hang_seconds
        self.unsendable_info = unsendable_info
        self.steps = 0

    def post_step(self, action):
        self.steps += 1
        if self.crash_after_steps is not None and self.steps >= self.crash_after_steps:
            sys.stderr.write(f"faulty scene: crashing on purpose at step {self.steps}\n")
            sys.stderr.flush()
            os._exit(self.crash_code)
        if self.hang_after_steps is not None and self.steps == self.hang_after_steps:
            time.sleep(self.hang_seconds)
        obs, reward, terminated, info = super().post_step(action)
        if self.unsendable_info:
            info = {"handle": object()}
        return obs, reward, terminated, info


if __name__ == "__main__":
    run_scene(FaultyCartPole)
