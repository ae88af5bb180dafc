"""TorchRL drives remote envs; scene keywords a scene rejects are TypeErrors;
a script that never serves gets a hint."""

from __future__ import annotations

import functools
import textwrap

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv.agent.launch.launcher import Launcher

ID = "remoteenv/CartPole-v0"


def test_rejected_scene_keyword_is_a_type_error_before_launching(monkeypatch):
    def no_launch(self, spec):
        raise AssertionError("a sim was launched")

    monkeypatch.setattr(Launcher, "start", no_launch)
    with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'") as err:
        gym.make(ID, frameskip=4)
    assert isinstance(err.value, remoteenv.LaunchError)
    with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'"):
        gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point", frameskip=4)


def _script(tmp_path, body: str):
    path = tmp_path / "my_scene.py"
    path.write_text(textwrap.dedent(body).format(scenes=remoteenv.scene_path("cartpole").rsplit("/", 1)[0]))
    return path


def test_a_keyword_the_sim_rejects_is_a_type_error_too(tmp_path):
    # The env class comes from another module: only the sim can tell.
    path = _script(
        tmp_path,
        """
        import sys
        sys.path.insert(0, "{scenes}")
        from cartpole_scene import CartPoleEnv
        from remoteenv.sim import run_scene

        if __name__ == "__main__":
            run_scene(CartPoleEnv)
        """,
    )
    with pytest.raises(remoteenv.SceneArgumentError, match="unexpected keyword argument 'frameskip'") as err:
        remoteenv.OpenAIRemoteEnv(path, frameskip=4)
    assert isinstance(err.value, TypeError)


def test_forgetting_run_scene_gets_a_hint(tmp_path):
    path = _script(
        tmp_path,
        """
        from remoteenv.sim import BaseEnv, run_scene

        class MyEnv(BaseEnv):
            pass

        def main():
            run_scene(MyEnv)
        """,
    )
    with pytest.raises(remoteenv.LaunchError, match=r"exited with code 0[\s\S]*did the script call run_scene"):
        remoteenv.OpenAIRemoteEnv(path)


torchrl_envs = pytest.importorskip("torchrl.envs")
torchrl_utils = pytest.importorskip("torchrl.envs.utils")


@pytest.mark.parametrize("num_envs", [0, 4])
def test_torchrl_gym_env_passes_check_env_specs_and_rolls_out(num_envs):
    # With num_envs, TorchRL's AsyncVectorEnv workers are fresh processes:
    # "module:id" makes them import remoteenv, which registers the id.
    env = torchrl_envs.GymEnv(f"remoteenv:{ID}", num_envs=num_envs) if num_envs else torchrl_envs.GymEnv(ID)
    try:
        torchrl_utils.check_env_specs(env)
        rollout = env.rollout(20, break_when_any_done=False)
        assert rollout.batch_size[-1] == 20
        assert rollout["next", "reward"].shape[-1] == 1
    finally:
        env.close()


@pytest.mark.parametrize("batched", ["SerialEnv", "ParallelEnv"])
def test_torchrl_batched_envs(batched):
    # "module:id" makes each worker import remoteenv (ParallelEnv's workers are fresh processes).
    make = functools.partial(torchrl_envs.GymEnv, f"remoteenv:{ID}")
    env = getattr(torchrl_envs, batched)(2, make)
    try:
        torchrl_utils.check_env_specs(env)
        rollout = env.rollout(10, break_when_any_done=False)
        assert tuple(rollout.batch_size) == (2, 10)
    finally:
        env.close()


def test_torchrl_gym_wrapper_over_remote_vector_env():
    venv = gym.make_vec(
        ID, num_envs=3, vectorization_mode="vector_entry_point", autoreset_mode=gym.vector.AutoresetMode.SAME_STEP
    )
    env = torchrl_envs.GymWrapper(venv)
    try:
        torchrl_utils.check_env_specs(env)
        rollout = env.rollout(30, break_when_any_done=False)
        assert tuple(rollout.batch_size) == (3, 30)
        assert np.all(rollout["next", "reward"].numpy() >= 0)
    finally:
        env.close()


def test_demo_runs_a_scene_script_with_its_own_policy(tmp_path, capsys):
    from remoteenv.cli import main as cli_main

    path = _script(
        tmp_path,
        """
        import sys
        sys.path.insert(0, "{scenes}")
        from cartpole_scene import CartPoleEnv
        from remoteenv.sim import run_scene

        def demo_policy(obs, t):
            return 1 if obs[2] + 0.5 * obs[3] > 0 else 0  # keeps the pole up

        if __name__ == "__main__":
            run_scene(CartPoleEnv)
        """,
    )
    assert cli_main(["demo", str(path), "--episodes", "1", "--max-steps", "200"]) == 0
    out = capsys.readouterr().out
    assert "return   200.000  steps  200 (truncated)" in out


def test_demo_runs_a_registered_id_and_refuses_unknown_ones(capsys):
    from remoteenv.cli import main as cli_main

    assert cli_main(["demo", "remoteenv/CartPole-v0", "--episodes", "1", "--continuous", "--max-steps", "100"]) == 0
    assert "steps  100 (truncated)" in capsys.readouterr().out  # the LQR controller of the shipped scene
    with pytest.raises(SystemExit, match="neither a shipped scene"):
        cli_main(["demo", "nobody/Nothing-v0"])
