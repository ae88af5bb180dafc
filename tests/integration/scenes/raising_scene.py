"""Test scene: continuous CartPole whose step raises for the action 0.5 (and
whose ``__init__`` raises with ``fail_init=True``)."""

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import run_scene


class RaisingCartPole(CartPoleEnv):
    def __init__(self, fail_init=False, **kwargs):
        if fail_init:
            raise ValueError("the pole length must be positive, got -1")
        kwargs["continuous"] = True
        super().__init__(**kwargs)

    def post_step(self, action):
        if action is not None and float(action[0]) == 0.5:
            raise ValueError("scene refuses the action 0.5")
        return super().post_step(action)


if __name__ == "__main__":
    run_scene(RaisingCartPole)
