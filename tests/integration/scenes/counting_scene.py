"""Test scene: CartPole whose every world, as it is made, appends a line to
``count_file`` (the layout gate's scratch world included). It says in its own
class body that it steps its worlds as one batch, as the shipped scenes do."""

from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import run_scene


class CountingCartPole(CartPoleEnv):
    stacked_hooks = True

    def __init__(self, count_file: str = "", render_mode: str | None = None, **kwargs):
        super().__init__(render_mode=render_mode, **kwargs)
        if count_file:
            with open(count_file, "a") as f:
                f.write(f"{render_mode}\n")


if __name__ == "__main__":
    run_scene(CountingCartPole)
