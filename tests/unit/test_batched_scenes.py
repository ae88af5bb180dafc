"""The batched step path (scene's batched hooks, physics on threads) against the
per-world path: byte-identical ``step_batch`` replies, seeds, resets and
autoresets included, for every shipped scene that implements the hooks."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from fakes import scene_class

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.stepping.batch_commands import BatchCommands
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.wire import protocol
from remoteenv.wire.protocol import OP_RESET, OP_STEP, OP_STEP_AUTORESET, OP_STEP_RESET
from remoteenv.wire.run_options.options import RunOptions


def _scene_class(name: str, cls: str) -> type[BaseEnv]:
    return scene_class(name, cls, f"{name}_scene_batched")


Reacher = _scene_class("reacher", "ReacherEnv")
CartPole = _scene_class("cartpole", "CartPoleEnv")
_made = itertools.count()


class TaggedReacher(Reacher):  # type: ignore[misc,valid-type]
    """Reacher whose starts say so in their infos (from every third world on)
    and whose steps add a numpy-bool info column: the replies of steps that
    start episodes then take the per-world encoding's other branches. World
    w of either path is tagged alike (K % 3 == 0)."""

    def __init__(self) -> None:
        super().__init__()
        self.tagged = next(_made) % 3 == 2

    def reset_model(self, options):
        obs, info = super().reset_model(options)
        return obs, {**info, "started": 1} if self.tagged else info

    @classmethod
    def reset_models(cls, envs, options):
        obs, infos = super().reset_models(envs, options)
        return obs, [{**info, "started": 1} if env.tagged else info for env, info in zip(envs, infos)]

    def post_step(self, action):
        obs, reward, terminated, info = super().post_step(action)
        return obs, reward, terminated, {**info, "near": np.bool_(info["reward_dist"] > -0.1)}

    @classmethod
    def post_steps(cls, envs, actions):
        batch = super().post_steps(envs, actions)
        batch.infos["near"] = batch.infos["reward_dist"] > -0.1
        return batch


SCENES = {
    "reacher": (lambda: Reacher(), {}),
    # Weights that differ between worlds (1 among them), the same for world w of both paths (K % 3 == 0).
    "reacher-weighted": (
        lambda: Reacher(reward_dist_weight=(1.0, 0.5, 2.0)[next(_made) % 3], reward_control_weight=0.25),
        {},
    ),
    "reacher-tagged": (lambda: TaggedReacher(), {}),
    "cartpole": (lambda: CartPole(), {}),
    "cartpole-continuous": (lambda: CartPole(continuous=True), {}),
}

K = 6


def _commands(make, threads: int, batched: bool) -> BatchCommands:
    envs = [make() for _ in range(K)]
    lock = LockStepping(envs)
    commands = BatchCommands(lock.worlds, envs[0].action_space, 0, threads=threads)
    if not batched:
        commands.close()
        commands.stepper = None  # the per-world path: each world's LockStepper.step
    return commands


def _actions(space, n: int, rng: np.random.Generator) -> np.ndarray:
    if hasattr(space, "n"):
        return rng.integers(0, space.n, size=n)
    return rng.uniform(space.low, space.high, size=(n, *space.shape)).astype(space.dtype)


def _requests(space, steps: int, seed: int):
    """A mix of full, partial and reordered step_batch requests with every op."""
    rng = np.random.default_rng(seed)
    for t in range(steps):
        n = K if t % 3 else int(rng.integers(1, K + 1))
        ops = rng.choice([OP_STEP, OP_STEP, OP_STEP_AUTORESET, OP_STEP_RESET, OP_RESET], size=n).tolist()
        if t % 4 == 0:
            ops = [OP_STEP_AUTORESET] * n  # the SAME_STEP common case
        actions = _actions(space, n, rng)
        msg = {"ops": ops, "actions": actions.tolist() if t % 7 == 0 else actions}
        if t % 5 == 0:
            msg["worlds"] = rng.permutation(K)[:n].tolist()
        yield msg


@pytest.mark.parametrize("scene", sorted(SCENES))
@pytest.mark.parametrize("threads", [1, 3])
def test_batched_and_per_world_paths_give_identical_replies(scene: str, threads: int) -> None:
    make, _ = SCENES[scene]
    batched, per_world = _commands(make, threads, True), _commands(make, threads, False)
    assert batched.stepper is not None
    space = batched.worlds[0].env.action_space
    try:
        seeds = {"worlds": list(range(K)), "seeds": [11 * w for w in range(K)], "options": None}
        first = batched.reset_batch(dict(seeds), None, None)
        assert protocol.pack(first) == protocol.pack(per_world.reset_batch(dict(seeds), None, None))
        finals = 0
        for msg in _requests(space, 300, seed=len(scene) + threads):
            a = batched.step_batch(dict(msg), None, None)
            b = per_world.step_batch(dict(msg), None, None)
            assert protocol.pack(a) == protocol.pack(b), msg
            finals += len(a["final"])
        assert finals > 10  # the resets within steps were exercised
        for wa, wb in zip(batched.worlds, per_world.worlds):  # the RNG streams too
            assert wa.env.np_random.integers(1 << 30) == wb.env.np_random.integers(1 << 30)
    finally:
        batched.close()
        for w in batched.worlds + per_world.worlds:
            w.env.close()


def test_a_reward_weight_set_between_steps_counts_from_the_next_step() -> None:
    """The batched hooks remember the worlds' reward weights between steps; a
    weight set on a world (as ``set_attr`` sets it) is used from the next step
    on, as the per-world path, which reads it at every step, uses it."""
    make, _ = SCENES["reacher"]
    batched, per_world, unchanged = _commands(make, 1, True), _commands(make, 1, False), _commands(make, 1, True)
    every = (batched, per_world, unchanged)
    rng = np.random.default_rng(3)
    try:
        for commands in every:
            commands.reset_batch({"worlds": list(range(K)), "seeds": list(range(K))}, None, None)
        for t in range(6):
            if t == 3:
                for commands in (batched, per_world):
                    commands.worlds[1].env.reward_dist_weight = 3.0
                    commands.worlds[4].env.reward_control_weight = 0.5
            msg = {"ops": [OP_STEP] * K, "actions": _actions(batched.worlds[0].env.action_space, K, rng)}
            a, b, c = (commands.step_batch(dict(msg), None, None) for commands in every)
            assert protocol.pack(a) == protocol.pack(b), t
            dist, ctrl = (a["info"]["columns"][key][0] for key in ("reward_dist", "reward_ctrl"))
            dist_1, ctrl_1 = (c["info"]["columns"][key][0] for key in ("reward_dist", "reward_ctrl"))
            if t < 3:
                assert protocol.pack(a) == protocol.pack(c), t
            else:  # exactly the weight's product, in the dtype post_step multiplies in
                assert dist[1] == dist_1[1] * 3.0 and ctrl[4] == ctrl_1[4] * np.float32(0.5), t
                assert np.delete(dist, 1).tolist() == np.delete(dist_1, 1).tolist()
                assert np.delete(ctrl, 4).tolist() == np.delete(ctrl_1, 4).tolist()
    finally:
        for commands in (batched, unchanged):
            commands.close()
        for w in batched.worlds + per_world.worlds + unchanged.worlds:
            w.env.close()


def test_plain_batch_reply_is_the_scenes_arrays() -> None:
    """A step of every world that resets none sends the scene's columns as they are."""
    make, _ = SCENES["reacher"]
    commands = _commands(make, 1, True)
    try:
        commands.reset_batch({"worlds": list(range(K)), "seeds": list(range(K))}, None, None)
        actions = np.zeros((K, 2), dtype=np.float32)
        reply = commands.step_batch({"ops": [OP_STEP] * K, "actions": actions}, None, None)
        assert reply["obs"].shape == (K, 10) and reply["final"] == []
        assert sorted(reply["info"]["columns"]) == ["reward_ctrl", "reward_dist"]
        values, present = reply["info"]["columns"]["reward_ctrl"]
        assert values.dtype == np.float32 and not values.any() and present == [True] * K  # Reacher-v5's type
    finally:
        commands.close()
        for w in commands.worlds:
            w.env.close()


def test_step_batch_refuses_repeated_worlds() -> None:
    from remoteenv.sim.transport.checks import RequestError

    make, _ = SCENES["cartpole"]
    commands = _commands(make, 1, True)
    try:
        commands.reset_batch({"worlds": list(range(K))}, None, None)
        with pytest.raises(RequestError, match="distinct"):
            commands.step_batch({"ops": [0, 0], "actions": [0, 1], "worlds": [2, 2]}, None, None)
    finally:
        commands.close()
        for w in commands.worlds:
            w.env.close()


@pytest.mark.parametrize("delays", [{"action_delay": 1}, {"obs_delay": 2}])
def test_worlds_with_delays_step_one_by_one(delays) -> None:
    """Delays live in each world's LockStepper: such worlds never take the batched path."""
    envs = [Reacher() for _ in range(2)]
    lock = LockStepping(envs, RunOptions(**delays))
    commands = BatchCommands(lock.worlds, envs[0].action_space, 0)
    try:
        assert commands.stepper is None
    finally:
        for env in envs:
            env.close()


@pytest.mark.parametrize(
    "wrong",
    [lambda obs: obs.astype(np.float32), lambda obs: obs[:, :9], lambda obs: obs.reshape(2, 2, 5)],
    ids=["dtype", "row-length", "row-shape"],
)
def test_batched_observations_are_checked_against_the_space(wrong) -> None:
    """The batched path checks what post_steps returns, as finish_tick does per world."""
    from remoteenv.sim.scene.obs_check import ObservationError

    class WrongObs(Reacher):  # type: ignore[misc,valid-type]
        @classmethod
        def post_steps(cls, envs, actions):
            result = super().post_steps(envs, actions)
            result.obs = wrong(result.obs)
            return result

    envs = [WrongObs() for _ in range(2)]
    commands = BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0)
    try:
        commands.reset_batch({"worlds": [0, 1]}, None, None)
        with pytest.raises(ObservationError, match="post_steps"):
            commands.step_batch({"ops": [0, 0], "actions": np.zeros((2, 2), np.float32)}, None, None)
    finally:
        commands.close()
        for env in envs:
            env.close()
