"""The worlds' batched reset (a scene's ``reset_models``) against each world's own
``reset``: the same start states, observations, infos and RNG streams, bit for
bit, in one ``mujoco.batch`` call or over each world's ``MjData``; a scene
without the hook keeps the per-world reset; a wrong result names the hook."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import pytest
from fakes import scene_class

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.step_check import StepResultError
from remoteenv.sim.stepping import batch_step
from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.batch_step import WorldsStepper
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.wire import protocol
from remoteenv.wire.protocol import OP_RESET, OP_STEP


def _scene_class(name: str, cls: str) -> type[BaseEnv]:
    return scene_class(name, cls, f"{name}_scene_reset")


Reacher = _scene_class("reacher", "ReacherEnv")
CartPole = _scene_class("cartpole", "CartPoleEnv")
SCENES = {"reacher": Reacher, "cartpole": CartPole}
K = 5
#: Everything a world's MjData holds that a reset writes or mj_forward derives.
FIELDS = ("time", "qpos", "qvel", "act", "ctrl", "qacc_warmstart", "xpos", "xquat", "qacc", "qfrc_bias", "cvel")


def _state(env: BaseEnv) -> dict[str, np.ndarray]:
    data = env.data
    return {name: np.array(getattr(data, name)) for name in FIELDS}


def _close(*worlds: Any) -> None:
    for env in worlds:
        env.close()


@pytest.mark.parametrize("batched", [True, False], ids=["mujoco-batch", "each-mjdata"])
@pytest.mark.parametrize("scene", sorted(SCENES))
def test_reset_models_starts_each_world_as_its_own_reset_does(
    scene: str, batched: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    if not batched:
        monkeypatch.setattr(batch_step, "available", lambda: False)
    cls = SCENES[scene]
    together, alone = [cls() for _ in range(K)], [cls() for _ in range(K)]
    stepper = WorldsStepper(together)
    assert stepper.resets_together and (stepper.batched is not None) == batched
    try:
        for w in range(K):
            together[w].seed_rng(7 * w)
            alone[w].seed_rng(7 * w)
        worlds = [3, 0, 4]  # a subset, out of order
        before = _state(together[1])
        obs, infos, times = stepper.reset(worlds, None)
        for j, w in enumerate(worlds):
            o, info = alone[w].reset()
            assert np.asarray(obs[j]).tobytes() == o.tobytes() and obs[j].dtype == o.dtype
            assert infos[j] == info and float(times[j]) == float(alone[w].data.time)
            mine, theirs = _state(together[w]), _state(alone[w])
            for name in FIELDS:
                assert mine[name].tobytes() == theirs[name].tobytes(), (w, name)
            assert together[w].np_random.integers(1 << 30) == alone[w].np_random.integers(1 << 30)
        for name, value in _state(together[1]).items():  # a world not named is left as it was
            assert value.tobytes() == before[name].tobytes(), name
        # The worlds step on from their start states as the per-world ones do.
        actions = np.zeros((K, *together[0].action_space.shape), together[0].action_space.dtype)
        if not actions.shape[1:]:
            actions = np.ones(K, dtype=np.int64)
        for w in range(K):
            if w not in worlds:
                alone[w].reset()
                together[w].reset()
        result = stepper.step(list(range(K)), actions)
        for w in range(K):
            o, *_ = alone[w].step(actions[w] if actions.ndim > 1 else int(actions[w]))
            assert np.asarray(result.obs[w]).tobytes() == o.tobytes(), w
    finally:
        stepper.close()
        _close(*together, *alone)


def test_a_scene_without_the_hook_resets_world_by_world() -> None:
    class OwnResetOnly(Reacher):  # type: ignore[misc,valid-type]
        reset_models = BaseEnv.reset_models  # the per-world default

    envs = [OwnResetOnly() for _ in range(2)]
    stepper = WorldsStepper(envs)
    try:
        assert not stepper.resets_together
    finally:
        stepper.close()
        _close(*envs)


def _commands(cls: type[BaseEnv], batched: bool) -> BatchCommands:
    envs = [cls() for _ in range(K)]
    commands = BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0)
    if not batched:
        commands.close()
        commands.stepper = None  # each world's LockStepper.reset
    return commands


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_reset_ticks_reply_as_the_per_world_resets_do(scene: str) -> None:
    """A vector env's reset (seeded), an all-world autoreset tick and a partial one."""
    cls = SCENES[scene]
    together, alone = _commands(cls, True), _commands(cls, False)
    space = together.worlds[0].env.action_space
    actions = np.zeros((K, *space.shape), space.dtype) if space.shape else np.ones(K, dtype=np.int64)
    try:
        seeds = {"worlds": list(range(K)), "seeds": [3 * w + 1 for w in range(K)]}
        assert protocol.pack(together.reset_batch(dict(seeds), None, None)) == protocol.pack(
            alone.reset_batch(dict(seeds), None, None)
        )
        for ops in ([OP_STEP] * K, [OP_RESET] * K, [OP_STEP, OP_RESET, OP_STEP, OP_RESET, OP_STEP], [OP_STEP] * K):
            msg = {"ops": ops, "actions": actions}
            assert protocol.pack(together.step_batch(dict(msg), None, None)) == protocol.pack(
                alone.step_batch(dict(msg), None, None)
            ), ops
        assert all(w.has_reset for w in together.worlds)
    finally:
        together.close()
        _close(*(w.env for w in together.worlds + alone.worlds))


@pytest.mark.parametrize(
    "result, match",
    [
        (lambda obs, infos: obs, "returned an array"),
        (lambda obs, infos: (obs[:1], infos), "for 2 worlds"),
        (lambda obs, infos: (obs, infos[:1]), "list of 2 dicts"),
        (lambda obs, infos: (obs.astype(np.float32), infos), "reset_models"),
    ],
    ids=["not-a-pair", "too-few-obs", "too-few-infos", "wrong-dtype"],
)
def test_a_wrong_reset_models_result_names_the_hook(result, match: str) -> None:
    from remoteenv.sim.scene.obs_check import ObservationError

    class Wrong(Reacher):  # type: ignore[misc,valid-type]
        @classmethod
        def reset_models(cls, envs, options):
            return result(*super().reset_models(envs, options))

    envs = [Wrong() for _ in range(2)]
    stepper = WorldsStepper(envs)
    try:
        with pytest.raises((StepResultError, ObservationError), match=match) as caught:
            stepper.reset([0, 1], None)
        assert "Wrong.reset_models" in str(caught.value) or "reset_models" in str(caught.value)
    finally:
        stepper.close()
        _close(*envs)


def test_the_data_fallback_resets_as_mj_resetData() -> None:
    """Without mujoco.batch the stacked state's reset is each world's ``mj_resetData``."""
    from remoteenv.sim.stepping.batch_worlds import data_state

    envs = [Reacher() for _ in range(2)]
    try:
        for env in envs:
            env.reset(seed=1)
            mujoco.mj_step(env.model, env.data, nstep=5)
        data_state(envs).reset()
        fresh = Reacher()
        mujoco.mj_resetData(fresh.model, fresh.data)
        for env in envs:
            for name in FIELDS:
                assert np.array_equal(getattr(env.data, name), getattr(fresh.data, name)), name
        fresh.close()
    finally:
        _close(*envs)
