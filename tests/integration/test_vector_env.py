"""RemoteVectorEnv: Gymnasium vector semantics, seeds, K worlds per process, cleanup.

The reference for "as Gymnasium specifies" is Gymnasium's own SyncVectorEnv
over single remote envs made with ``gymnasium.make`` (TimeLimit included),
stepped with the same seeds and actions.
"""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
import pytest
from equality import assert_same
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import remoteenv
from remoteenv import RemoteVectorEnv

CARTPOLE = "remoteenv/CartPole-v0"
REACHER = "remoteenv/Reacher-v0"


def reference_vector(env_id, num_envs, max_episode_steps, mode, **kwargs):
    """Gymnasium's SyncVectorEnv of single remote envs: the behaviour to match."""
    return SyncVectorEnv(
        [lambda: gym.make(env_id, max_episode_steps=max_episode_steps, **kwargs)] * num_envs,
        autoreset_mode=mode,
    )


def run_side_by_side(remote, reference, steps, seed, action_seed, disabled=False):
    """Step both with the same actions; compare every returned value. Returns the
    number of episode ends seen (so a test can check it exercised autoreset)."""
    ro, ri = remote.reset(seed=seed)
    fo, fi = reference.reset(seed=seed)
    assert_same(ro, fo, "reset obs")
    assert_same(ri, fi, "reset info")
    remote.action_space.seed(action_seed)
    ends = 0
    for t in range(steps):
        actions = remote.action_space.sample()
        r = remote.step(actions)
        f = reference.step(actions)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), r, f):
            assert_same(x, y, f"step {t} {name}")
        ended = r[2] | r[3]
        ends += int(ended.sum())
        if disabled and ended.any():
            ro, ri = remote.reset(options={"reset_mask": ended})
            fo, fi = reference.reset(options={"reset_mask": ended.copy()})
            assert_same(ro, fo, f"step {t} masked reset obs")
            assert_same(ri, fi, f"step {t} masked reset info")
    return ends


@pytest.mark.parametrize("mode", list(AutoresetMode))
@pytest.mark.parametrize("k", [1, 2, 3])
def test_cartpole_matches_sync_vector_env_of_single_envs(closing, mode, k):
    # 3 worlds; K=2 leaves an unused world in the second process.
    remote = gym.make_vec(
        CARTPOLE,
        num_envs=3,
        vectorization_mode="vector_entry_point",
        envs_per_process=k,
        autoreset_mode=mode,
        max_episode_steps=15,
    )
    closing(remote)
    reference = reference_vector(CARTPOLE, 3, 15, mode)
    closing(reference)
    assert remote.metadata["autoreset_mode"] == mode
    assert len(remote.unwrapped.slices) == -(-3 // k)
    ends = run_side_by_side(remote, reference, 60, seed=7, action_seed=1, disabled=mode == AutoresetMode.DISABLED)
    assert ends >= 3  # terminations and 15-step truncations both happened


@pytest.mark.parametrize("k", [1, 2])
def test_reacher_matches_sync_vector_env_with_box_actions(closing, k):
    remote = gym.make_vec(
        REACHER,
        num_envs=4,
        vectorization_mode="vector_entry_point",
        envs_per_process=k,
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    closing(remote)
    assert remote.unwrapped.max_episode_steps == 50  # taken from the registry spec
    reference = reference_vector(REACHER, 4, 50, AutoresetMode.SAME_STEP)
    closing(reference)
    assert remote.single_observation_space == reference.single_observation_space
    assert remote.single_action_space == reference.single_action_space
    assert remote.observation_space == reference.observation_space
    ends = run_side_by_side(remote, reference, 55, seed=3, action_seed=2)
    assert ends == 4


def test_same_seeds_give_the_trajectories_of_single_envs(closing):
    n, seed = 3, 11
    vec = RemoteVectorEnv(remoteenv.scene_path("reacher"), n, envs_per_process=2, max_episode_steps=50)
    closing(vec)
    singles = [gym.make(REACHER) for _ in range(n)]
    for env in singles:
        closing(env)
    obs, _ = vec.reset(seed=seed)
    single_obs = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(single_obs))
    rng = np.random.default_rng(0)
    for _ in range(20):
        actions = rng.uniform(-1, 1, size=(n, 2)).astype(np.float32)
        obs, rew, term, trunc, info = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rew[i] == r and term[i] == te and trunc[i] == tr
            assert info["reward_dist"][i] == inf["reward_dist"] and info["_reward_dist"][i]


def test_next_step_reset_step_ignores_the_action(closing):
    kwargs = dict(num_envs=2, vectorization_mode="vector_entry_point", envs_per_process=2, max_episode_steps=3)
    a = gym.make_vec(REACHER, **kwargs)
    b = gym.make_vec(REACHER, **kwargs)
    closing(a)
    closing(b)
    a.reset(seed=5)
    b.reset(seed=5)
    same = np.zeros((2, 2), dtype=np.float32)
    for _ in range(3):
        ra, rb = a.step(same), b.step(same)
    assert ra[3].all() and rb[3].all()  # truncated at the limit
    # The reset step: wildly different actions, identical results.
    oa, rwa, ta, tra, ia = a.step(np.full((2, 2), 1.0, dtype=np.float32))
    ob, rwb, tb, trb, ib = b.step(np.full((2, 2), -1.0, dtype=np.float32))
    np.testing.assert_array_equal(oa, ob)
    assert (rwa == 0).all() and not ta.any() and not tra.any()
    assert_same(ia, ib)
    # The next step counts from the new episode.
    _, _, _, trunc, _ = a.step(same)
    assert not trunc.any()


def test_disabled_mode_requires_reset_mask(closing):
    env = RemoteVectorEnv(
        remoteenv.scene_path("cartpole"), 2, envs_per_process=2, autoreset_mode="Disabled", max_episode_steps=2
    )
    closing(env)
    obs, _ = env.reset(seed=0)
    env.step(np.array([0, 1]))
    _, _, _, trunc, _ = env.step(np.array([0, 1]))
    assert trunc.all()
    with pytest.raises(RuntimeError, match="reset_mask"):
        env.step(np.array([0, 1]))
    mask = np.array([True, False])
    before, _ = env.reset(seed=None, options={"reset_mask": np.array([True, True])})
    after, info = env.reset(options={"reset_mask": mask})
    np.testing.assert_array_equal(after[1], before[1])  # the unmasked world kept its obs
    with pytest.raises(TypeError, match="reset_mask"):
        env.reset(options={"reset_mask": [True, False]})


def test_invalid_actions_name_the_world(closing):
    env = RemoteVectorEnv(remoteenv.scene_path("reacher"), 2)
    closing(env)
    env.reset(seed=0)
    bad = np.zeros((2, 2), dtype=np.float32)
    bad[1, 0] = 2.0
    with pytest.raises(ValueError, match="world 1"):
        env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((3, 2), dtype=np.float32))
    env.step(np.zeros((2, 2), dtype=np.float32))  # still usable


def test_real_time_needs_one_world_per_process():
    with pytest.raises(ValueError, match="envs_per_process=1"):
        RemoteVectorEnv(remoteenv.scene_path("reacher"), 4, envs_per_process=2, real_time=True)


def test_real_time_vector_env_steps(closing):
    env = gym.make_vec(
        REACHER, num_envs=2, vectorization_mode="vector_entry_point", real_time=True, max_episode_steps=4
    )
    closing(env)
    assert env.unwrapped.envs_per_process == 1
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2, 10)
    truncs = []
    for _ in range(5):
        obs, rew, term, trunc, info = env.step(np.zeros((2, 2), dtype=np.float32))
        assert obs.shape == (2, 10) and rew.dtype == np.float64
        truncs.append(trunc.copy())
    assert truncs[3].all() and not truncs[4].any()  # truncated at 4, reset on the 5th


def test_render_returns_one_frame_per_world(closing):
    env = RemoteVectorEnv(
        remoteenv.scene_path("reacher"), 3, envs_per_process=2, render_mode="rgb_array", width=64, height=48
    )
    closing(env)
    env.reset(seed=0)
    frames = env.render()
    assert len(frames) == 3 and all(f.shape == (48, 64, 3) and f.dtype == np.uint8 for f in frames)


def test_close_leaves_no_process_or_socket_file(pid_alive, wait_gone):
    env = RemoteVectorEnv(remoteenv.scene_path("cartpole"), 4, envs_per_process=2)
    pids = env.pids
    workdir = env.launcher.workdir
    sockets = [os.path.join(workdir, f) for f in os.listdir(workdir) if f.endswith(".sock")]
    assert len(pids) == 2 and len(sockets) == 2
    env.reset(seed=0)
    env.step(np.array([0, 1, 0, 1]))
    env.close()
    assert env.closed and env.pids == []
    assert all(wait_gone(pid) for pid in pids)
    assert not os.path.exists(workdir)
    assert not any(os.path.exists(s) for s in sockets)
    env.close()  # idempotent
