"""Scene mistakes reach the agent named: the scene, the hook and the value."""

from __future__ import annotations

import textwrap

import gymnasium as gym
import numpy as np
import pytest

from remoteenv import LaunchError, OpenAIRemoteEnv, RemoteVectorEnv, SceneError

SCRIPT = """
import numpy as np
from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim import BaseEnv, run_scene


class {name}(CartPoleEnv):
    # BaseEnv's batched hooks, so that the vector env's batches call post_step too.
    prepare_steps = classmethod(BaseEnv.prepare_steps.__func__)
    post_steps = classmethod(BaseEnv.post_steps.__func__)

    def post_step(self, action):
        obs, reward, terminated, info = super().post_step(action)
        return {returns}


if __name__ == "__main__":
    run_scene({name})
"""


def _scene(tmp_path, name: str, returns: str) -> str:
    path = tmp_path / f"{name.lower()}_scene.py"
    path.write_text(textwrap.dedent(SCRIPT.format(name=name, returns=returns)))
    return str(path)


@pytest.mark.parametrize(
    ("name", "returns", "says"),
    [
        (
            "ArrayReward",
            "obs, np.array([reward, 0.0]), terminated, info",
            "ArrayReward.post_step returned reward an array",
        ),
        ("NoneFlag", "obs, reward, None, info", "NoneFlag.post_step returned terminated None (NoneType)"),
    ],
)
def test_single_and_vector_envs_name_the_mistake(tmp_path, name, returns, says):
    script = _scene(tmp_path, name, returns)
    env = gym.wrappers.TimeLimit(OpenAIRemoteEnv(script), 10)
    try:
        env.reset(seed=0)
        with pytest.raises(SceneError, match="post_step returned") as err:
            env.step(0)
        assert says in str(err.value)
        env.reset(seed=1)  # the sim keeps serving
    finally:
        env.close()
    envs = RemoteVectorEnv(script, 2)
    try:
        assert envs.envs_per_process == 2  # one step_batch steps both worlds
        envs.reset(seed=0)
        with pytest.raises(SceneError) as err:
            envs.step(np.zeros(2, dtype=np.int64))
        assert says in str(err.value)
    finally:
        envs.close()


def test_a_relative_model_path_fails_with_the_fix(tmp_path):
    path = tmp_path / "relative_scene.py"
    path.write_text(
        textwrap.dedent(
            """
            from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
            from remoteenv.sim import BaseEnv, run_scene


            class Relative(CartPoleEnv):
                def __init__(self, **kwargs):
                    space = CartPoleEnv()
                    BaseEnv.__init__(self, "relative.xml", 10, space.observation_space, space.action_space)


            if __name__ == "__main__":
                run_scene(Relative)
            """
        )
    )
    with pytest.raises(LaunchError) as err:
        OpenAIRemoteEnv(str(path))
    text = str(err.value)
    assert "Relative: MJCF model file 'relative.xml' not found" in text
    assert "os.path.dirname(os.path.abspath(__file__))" in text
