"""Test scene: CartPole whose worlds do not step as one batch (no stacked
hooks): its Python runs world by world, as a scene written without batch
hooks does."""

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import run_scene


class PerWorldCartPole(CartPoleEnv):
    stacked_hooks = False


if __name__ == "__main__":
    run_scene(PerWorldCartPole)
