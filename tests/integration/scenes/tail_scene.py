"""Test scene: Reacher (its worlds stepped as one batch) whose stacked
``prepare_steps`` first sleeps ``head_s`` seconds (the agent is then surely
asleep when the physics is done) and whose stacked ``post_steps`` first sleeps
``tail_s`` seconds (a tick slow after its physics, as a scene that renders in
its hook is), then raises when a world's first action component is exactly 0.5."""

import time

from remoteenv.scenes.reacher.reacher_scene import ReacherEnv
from remoteenv.sim import run_scene


class TailReacher(ReacherEnv):
    stacked_hooks = True

    def __init__(self, head_s: float = 0.0, tail_s: float = 0.0, **kwargs):
        super().__init__(**kwargs)
        self.head_s, self.tail_s = float(head_s), float(tail_s)

    @classmethod
    def prepare_steps(cls, envs, actions):
        if envs[0].head_s:
            time.sleep(envs[0].head_s)
        super().prepare_steps(envs, actions)

    @classmethod
    def post_steps(cls, envs, actions):
        if envs[0].tail_s:
            time.sleep(envs[0].tail_s)
        if (actions[:, 0] == 0.5).any():
            raise ValueError("scene refuses the action 0.5")
        return super().post_steps(envs, actions)


if __name__ == "__main__":
    run_scene(TailReacher)
