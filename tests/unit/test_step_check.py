"""A scene's step results are checked where the scene returns them, on every path:
a mistake names the scene, the hook and the value."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import remoteenv
from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.scene.step_check import StepResultError, check_batch, unpack_step
from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.sim.stepping.real_time import RealTimeStepping

OBS = np.zeros(4, dtype=np.float32)


def _cartpole() -> type[BaseEnv]:
    spec = importlib.util.spec_from_file_location("cartpole_scene_step_check", remoteenv.scene_path("cartpole"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.CartPoleEnv


CartPole = _cartpole()


@pytest.mark.parametrize(
    ("result", "says"),
    [
        ((OBS, np.array([1.0, 2.0]), False, {}), "reward an array of dtype float64 and shape (2,)"),
        ((OBS, None, False, {}), "reward None (NoneType)"),
        ((OBS, True, False, {}), "reward True (bool)"),
        ((OBS, 1.0, None, {}), "terminated None (NoneType)"),
        ((OBS, 1.0, 1, {}), "terminated 1 (int)"),
        ((OBS, 1.0, np.array([True]), {}), "terminated an array of dtype bool and shape (1,)"),
        ((OBS, 1.0, False, None), "info None (NoneType)"),
        ((OBS, 1.0, False, False, {}), "5 values"),
    ],
)
def test_wrong_step_results_name_scene_hook_and_value(result, says) -> None:
    with pytest.raises(StepResultError) as err:
        unpack_step(result, scene="MyScene", hook="post_step")
    text = str(err.value)
    assert text.startswith("MyScene.post_step returned ") and says in text
    assert isinstance(err.value, TypeError)


def test_right_step_results_pass_unchanged() -> None:
    for reward in (1.0, 1, np.float32(0.5), np.float64(-2.0), np.int64(3), np.array(1.5)):
        for flag in (True, False, np.bool_(True)):
            out = unpack_step((OBS, reward, flag, {"k": 1}), scene="S", hook="post_step")
            assert out[1] is reward and out[2] is flag


def test_finite_only_when_asked() -> None:
    unpack_step((OBS, float("nan"), False, {}), scene="S", hook="post_step")
    with pytest.raises(StepResultError, match="reward nan"):
        unpack_step((OBS, float("nan"), False, {}), scene="S", hook="post_step", finite=True)


def _batch(**overrides) -> BatchResult:
    fields = {
        "obs": np.zeros((3, 4), np.float32),
        "reward": np.ones(3),
        "terminated": np.zeros(3, np.bool_),
        "infos": {},
    }
    fields.update(overrides)
    return BatchResult(**fields)


@pytest.mark.parametrize(
    ("batch", "says"),
    [
        (_batch(reward=np.ones((3, 1))), "reward an array of dtype float64 and shape (3, 1) for 3 worlds"),
        (_batch(reward=[1.0, 1.0, 1.0]), "reward [1.0, 1.0, 1.0] (list) for 3 worlds"),
        (_batch(terminated=np.zeros(3, np.int64)), "terminated an array of dtype int64 and shape (3,)"),
        (_batch(terminated=None), "terminated None"),
        (_batch(obs=np.zeros((2, 4), np.float32)), "obs an array of dtype float32 and shape (2, 4) for 3 worlds"),
        (_batch(infos=[{}, {}]), "infos [{}, {}]"),
        ((np.zeros((3, 4)), np.ones(3), np.zeros(3, bool), {}), "return a remoteenv.sim.BatchResult"),
    ],
)
def test_wrong_batches_name_scene_hook_and_value(batch, says) -> None:
    with pytest.raises(StepResultError) as err:
        check_batch(batch, 3, scene="MyScene", hook="post_steps")
    assert str(err.value).startswith("MyScene.post_steps returned ") and says in str(err.value)


def test_finite_batches_only_when_asked() -> None:
    obs = np.zeros((3, 4), np.float32)
    obs[1, 2] = np.nan
    check_batch(_batch(obs=obs), 3, scene="S", hook="post_steps")
    with pytest.raises(StepResultError, match="world 1's observation with 1 NaN or infinite value"):
        check_batch(_batch(obs=obs), 3, scene="S", hook="post_steps", finite=True)
    with pytest.raises(StepResultError, match="rewards"):
        check_batch(_batch(reward=np.array([1.0, np.inf, 0.0])), 3, scene="S", hook="post_steps", finite=True)


# ---------------------------------------------------------------- every path of a scene


class ArrayReward(CartPole):  # type: ignore[misc,valid-type]
    def post_step(self, action):
        obs, reward, terminated, info = super().post_step(action)
        return obs, np.array([reward, reward]), terminated, info


class NoneTerminated(CartPole):  # type: ignore[misc,valid-type]
    def post_step(self, action):
        obs, reward, terminated, info = super().post_step(action)
        return obs, reward, None, info


class NanObs(CartPole):  # type: ignore[misc,valid-type]
    check_finite = True

    def post_step(self, action):
        obs, reward, terminated, info = super().post_step(action)
        obs[0] = np.nan
        return obs, reward, terminated, info


class BatchedArrayTerminated(CartPole):  # type: ignore[misc,valid-type]
    @classmethod
    def post_steps(cls, envs, actions):
        result = super().post_steps(envs, actions)
        result.terminated = result.terminated.astype(np.int64)
        return result


def _per_world_hooks(cls):
    """``cls`` with BaseEnv's batched hooks, which call the per-world ones."""
    return type(
        cls.__name__,
        (cls,),
        {
            "prepare_steps": classmethod(BaseEnv.prepare_steps.__func__),  # type: ignore[attr-defined]
            "post_steps": classmethod(BaseEnv.post_steps.__func__),  # type: ignore[attr-defined]
        },
    )


MISTAKES = [
    (ArrayReward, "ArrayReward.post_step returned reward an array", "post_step"),
    (NoneTerminated, "NoneTerminated.post_step returned terminated None", "post_step"),
    (NanObs, "NanObs.post_step", "NaN"),
]


@pytest.mark.parametrize(("cls", "says", "also"), MISTAKES)
def test_single_world_lock_step(cls, says, also) -> None:
    env = cls()
    try:
        world = LockStepping([env]).worlds[0]
        world.reset(seed=0, options=None)
        with pytest.raises(StepResultError) as err:
            world.step(1)
        assert says in str(err.value) and also in str(err.value)
    finally:
        env.close()


@pytest.mark.parametrize(("cls", "says", "also"), MISTAKES)
def test_single_world_real_time(cls, says, also) -> None:
    env = cls()
    clock = [100.0]  # a number the test sets: nothing waits
    try:
        stepping = RealTimeStepping([env], clock=lambda: clock[0])
        world = stepping.worlds[0]
        world.reset(seed=0, options=None)
        stepping.start_clocks(clock[0])
        world.submit(7, 1, None, None)
        got: list = []
        for _ in range(10 * env.frame_skip):
            deadline = world.next_deadline()
            assert deadline is not None
            clock[0] = deadline
            got = list(stepping.run_due(clock[0]))
            if got:
                break
        reply = got[0][2]
        assert reply["seq"] == 7 and reply["ok"] is False and reply["error"]["kind"] == "scene"
        assert "StepResultError" in reply["error"]["message"] and says in reply["error"]["message"]
    finally:
        env.close()


@pytest.mark.parametrize(
    ("cls", "says"),
    [
        # BaseEnv's batched hooks, which call the per-world ones.
        (_per_world_hooks(ArrayReward), "ArrayReward.post_step returned reward an array"),
        (_per_world_hooks(NoneTerminated), "NoneTerminated.post_step returned terminated None"),
        (_per_world_hooks(NanObs), "NanObs.post_step returned world 0's observation with 1 NaN"),
        # The scene's own batched hooks.
        (BatchedArrayTerminated, "BatchedArrayTerminated.post_steps returned terminated an array of dtype int64"),
    ],
)
def test_batched_path(cls, says) -> None:
    envs = [cls() for _ in range(3)]
    commands = BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0)
    try:
        assert commands.stepper is not None  # the worlds step together
        commands.reset_batch({"worlds": [0, 1, 2]}, None, None)
        with pytest.raises(StepResultError) as err:
            commands.step_batch({"ops": [0, 0, 0], "actions": np.ones(3, np.int64)}, None, None)
        assert says in str(err.value)
    finally:
        commands.close()
        for env in envs:
            env.close()


def test_reset_model_must_return_obs_and_info() -> None:
    class ObsOnly(CartPole):  # type: ignore[misc,valid-type]
        def reset_model(self, options):
            return super().reset_model(options)[0]

    env = ObsOnly()
    try:
        with pytest.raises(StepResultError, match=r"ObsOnly.reset_model returned .* \(obs, info\)"):
            env.reset(seed=0)
    finally:
        env.close()


def test_a_relative_model_path_that_is_not_there_gets_the_fix(tmp_path, monkeypatch) -> None:
    class Relative(CartPole):  # type: ignore[misc,valid-type]
        def __init__(self):
            BaseEnv.__init__(self, "cartpole.xml", 10, CartPole().observation_space, CartPole().action_space)

    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError) as err:
        Relative()
    text = str(err.value)
    assert text.startswith("Relative: MJCF model file 'cartpole.xml' not found")
    assert str(tmp_path) in text and "os.path.dirname(os.path.abspath(__file__))" in text
