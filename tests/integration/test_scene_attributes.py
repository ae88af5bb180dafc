"""call / get_attr / set_attr reach each world's scene, as SyncVectorEnv does; envs pickle."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import remoteenv
from remoteenv.integrations.sb3 import SB3VecEnv

ID = "remoteenv/CartPole-v0"


@pytest.fixture
def vec_pair():
    """A RemoteVectorEnv (two worlds per process, two processes) and a
    SyncVectorEnv of single remote envs, both with 3 worlds of CartPole."""
    remote = gym.make_vec(ID, num_envs=3, vectorization_mode="vector_entry_point", envs_per_process=2)
    sync = gym.make_vec(ID, num_envs=3, vectorization_mode="sync")
    yield remote, sync
    remote.close()
    sync.close()


def test_vector_call_get_set_equal_sync_vector_env(vec_pair):
    remote, sync = vec_pair
    for name in ("pole_mass", "dt", "render_mode", "observation_space", "action_space", "continuous"):
        assert remote.get_attr(name) == sync.get_attr(name), name
    assert remote.get_attr("metadata") == sync.get_attr("metadata")
    for env in (remote, sync):
        env.set_attr("pole_mass", [0.05, 0.2, 0.4])
        assert env.get_attr("pole_mass") == pytest.approx((0.05, 0.2, 0.4))
        env.set_attr("pole_mass", 0.3)  # one value for every world
        assert env.get_attr("pole_mass") == pytest.approx((0.3, 0.3, 0.3))
        assert env.call("force_fraction", 1) == (1.0, 1.0, 1.0)
        with pytest.raises(ValueError, match="length equal to the number of environments"):
            env.set_attr("pole_mass", [0.1, 0.2])
        with pytest.raises(AttributeError):
            env.get_attr("no_such_attribute")


def test_per_world_parameters_change_the_physics(vec_pair):
    remote, _ = vec_pair
    remote.set_attr("pole_mass", [0.1, 0.1, 1.0])
    remote.reset(seed=[5, 5, 5])
    actions = np.ones(3, dtype=np.int64)
    for _ in range(5):
        obs, *_ = remote.step(actions)
    np.testing.assert_array_equal(obs[0], obs[1])  # same mass, same seed, same actions
    assert not np.array_equal(obs[0], obs[2])


def test_refusals_say_why(vec_pair):
    remote, _ = vec_pair
    with pytest.raises(AttributeError, match="private"):
        remote.get_attr("_terminated")
    with pytest.raises(remoteenv.RemoteEnvError, match="drives the world"):
        remote.call("step", 1)
    with pytest.raises(TypeError, match="cannot cross the wire") as err:
        remote.get_attr("model")
    assert "CartPoleEnv (world 0 of sim instance 0)" in str(err.value)
    with pytest.raises(AttributeError, match="agent-side env"):
        remote.set_attr("render_mode", "rgb_array")
    with pytest.raises(remoteenv.SceneError, match="pole_mass must be > 0"):
        remote.set_attr("pole_mass", -1.0)
    assert remote.call_at([2, 0], "force_fraction", 0) == (-1.0, -1.0)


def test_single_env_reaches_its_scene():
    env = gym.make(ID)
    try:
        inner = env.unwrapped
        assert inner.call("force_fraction", 1) == 1.0
        inner.set_scene_attr("pole_mass", 0.25)
        assert inner.get_scene_attr("pole_mass") == pytest.approx(0.25)
        method = env.get_wrapper_attr("force_fraction")  # through gym.make's wrappers
        assert method(0) == -1.0
        assert env.get_wrapper_attr("dt") == pytest.approx(0.02)
        env.set_wrapper_attr("pole_mass", 0.5)
        assert env.get_wrapper_attr("pole_mass") == pytest.approx(0.5)
    finally:
        env.close()


def test_sb3_env_method_get_set_attr_with_indices():
    venv = SB3VecEnv(gym.make_vec(ID, num_envs=3, vectorization_mode="vector_entry_point"))
    try:
        venv.set_attr("pole_mass", 0.4, indices=[1])
        assert venv.get_attr("pole_mass") == pytest.approx([0.1, 0.4, 0.1])
        assert venv.get_attr("pole_mass", indices=[1, 2]) == pytest.approx([0.4, 0.1])
        venv.set_attr("pole_mass", 0.2)
        assert venv.get_attr("pole_mass") == pytest.approx([0.2, 0.2, 0.2])
        assert venv.env_method("force_fraction", 1, indices=[0, 2]) == [1.0, 1.0]
        assert venv.env_method("force_fraction", 0) == [-1.0, -1.0, -1.0]
    finally:
        venv.close()


def _rollout(env, seed: int, n: int = 20) -> list[np.ndarray]:
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for t in range(n):
        obs, *_ = env.step(t % 2)
        out.append(obs)
    return out


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_single_env_pickles_into_a_fresh_sim(how):
    env = gym.make(ID)
    try:
        copied = pickle.loads(pickle.dumps(env)) if how == "pickle" else copy.deepcopy(env)
        try:
            assert copied.unwrapped.pid != env.unwrapped.pid
            assert copied.spec == env.spec
            np.testing.assert_array_equal(np.stack(_rollout(env, 3)), np.stack(_rollout(copied, 3)))
        finally:
            copied.close()
    finally:
        env.close()


def test_vector_env_pickles_into_fresh_sims():
    venv = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point", continuous=True)
    try:
        copied = pickle.loads(pickle.dumps(venv))
        try:
            assert set(copied.pids).isdisjoint(venv.pids)
            assert copied.get_attr("continuous") == (True, True)
            a, _ = venv.reset(seed=1)
            b, _ = copied.reset(seed=1)
            np.testing.assert_array_equal(a, b)
        finally:
            copied.close()
    finally:
        venv.close()


def test_an_env_built_around_an_object_says_to_pass_a_factory():
    launcher = remoteenv.Launcher()
    env = remoteenv.OpenAIRemoteEnv(remoteenv.scene_path("cartpole"), launcher=launcher)
    try:
        with pytest.raises(TypeError, match="Pass a factory"):
            pickle.dumps(env)
    finally:
        env.close()


def test_seeds_and_frames_as_sync_vector_env_gives_them():
    kwargs = {"render_mode": "rgb_array", "width": 40, "height": 30}
    remote = gym.make_vec(ID, num_envs=3, vectorization_mode="vector_entry_point", envs_per_process=2, **kwargs)
    sync = gym.make_vec(ID, num_envs=3, vectorization_mode="sync", **kwargs)
    try:
        for env in (remote, sync):
            env.reset(seed=5)
            assert env.np_random_seed == (5, 6, 7)
            assert env.get_attr("np_random_seed") == (5, 6, 7)
            env.reset()  # no seed: each world's RNG stream goes on
            assert env.np_random_seed == (5, 6, 7)
            env.reset(seed=[9, None, 1])
            assert env.np_random_seed == (9, 6, 1)
        remote_frames, sync_frames = remote.call("render"), sync.call("render")
        assert len(remote_frames) == 3 and remote_frames[0].shape == (30, 40, 3)
        for a, b in zip(remote_frames, sync_frames):
            np.testing.assert_array_equal(a, b)  # same seeds, same states, same pictures
        assert len(remote.call_at([2], "render")) == 1
        np.testing.assert_array_equal(remote.render()[1], remote_frames[1])
    finally:
        remote.close()
        sync.close()
    unrendered = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point")
    try:
        unrendered.reset(seed=0)
        assert unrendered.call("render") == (None, None)  # as SyncVectorEnv without a render mode
    finally:
        unrendered.close()


def test_unseeded_np_random_seed_is_each_worlds_as_sync_vector_env_gives_it(vec_pair):
    """Issue 28, item 6: before any seeded reset, Gymnasium's seed is a random
    128-bit integer, beyond msgpack's range; it used to fail to cross the wire."""
    remote, sync = vec_pair
    for env in (remote, sync):
        seeds = env.get_attr("np_random_seed")
        assert len(seeds) == 3 and all(type(s) is int and 0 <= s < 2**128 for s in seeds), seeds
        assert len(set(seeds)) == 3 and max(seeds) >= 2**64  # 128-bit draws: at least one past the old range
        env.reset()  # no seed: the streams go on, the seeds stay
        assert env.get_attr("np_random_seed") == seeds


def test_the_model_and_data_say_they_live_in_the_sim(vec_pair):
    """Issue 28, item 6: a bare AttributeError gave no word of where they are."""
    remote, _ = vec_pair
    single = gym.make(ID)
    try:
        for env, reach in ((single.unwrapped, "get_scene_attr"), (remote.unwrapped, "get_attr")):
            for name in ("model", "data"):
                with pytest.raises(AttributeError, match=f"MuJoCo {name} lives in the sim process.*{reach}.*call"):
                    getattr(env, name)
                assert not hasattr(env, name)
        with pytest.raises(AttributeError, match="no attribute 'no_such_thing'"):
            single.unwrapped.no_such_thing  # noqa: B018
    finally:
        single.close()
