"""RemoteVectorEnv's asynchronous APIs against its synchronous step.

``send``/``recv`` (EnvPool's) and ``step_async``/``step_wait`` (Gymnasium's)
must give every world the trajectory ``step`` gives it with the same seeds
and actions, autoresets and time limits included; the async path's worlds
may come back in any order, so trajectories are compared per world.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import remoteenv  # noqa: F401  (registers the ids)
from remoteenv.agent.errors import StateError

REACHER = "remoteenv/Reacher-v0"
CARTPOLE = "remoteenv/CartPole-v0"


def _action(env_id: str, world: int, t: int) -> np.ndarray:
    """A fixed action for world ``world``'s ``t``-th step (so any order of steps gives the same)."""
    rng = np.random.default_rng(1000 * world + t)
    if env_id == CARTPOLE:
        return np.asarray(rng.integers(0, 2))
    return rng.uniform(-1, 1, size=2).astype(np.float32)


def _sync_trajectories(env, env_id: str, n: int, steps: int) -> dict[int, list[tuple]]:
    out: dict[int, list[tuple]] = {w: [] for w in range(n)}
    env.reset(seed=5)
    for t in range(steps):
        obs, rew, term, trunc, _ = env.step(np.stack([_action(env_id, w, t) for w in range(n)]))
        for w in range(n):
            out[w].append((obs[w].tobytes(), float(rew[w]), bool(term[w]), bool(trunc[w])))
    return out


@pytest.mark.parametrize("env_id,k,batch", [(REACHER, 3, 2), (CARTPOLE, 4, 3), (REACHER, 6, 6)])
def test_send_recv_gives_each_world_its_synchronous_trajectory(closing, env_id, k, batch):
    n, steps = 6, 70  # Reacher's 50-step limit and CartPole's terminations reset worlds
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", envs_per_process=k)
    closing(sync)
    expected = _sync_trajectories(sync, env_id, n, steps)
    env = gym.make_vec(
        env_id, num_envs=n, vectorization_mode="vector_entry_point", envs_per_process=k, batch_size=batch
    )
    closing(env)
    env.reset(seed=5)
    got: dict[int, list[tuple]] = {w: [] for w in range(n)}
    env.send(np.stack([_action(env_id, w, 0) for w in range(n)]))
    # Every world returned is sent its next action at once (worlds done with
    # their steps keep going, unrecorded), so batch_size worlds are always due.
    while any(len(v) < steps for v in got.values()):
        obs, rew, term, trunc, info = env.recv()
        ids = info["env_id"]
        assert obs.shape[0] == len(ids) == batch and len(set(ids.tolist())) == batch
        for j, w in enumerate(ids.tolist()):
            if len(got[w]) < steps:
                got[w].append((obs[j].tobytes(), float(rew[j]), bool(term[j]), bool(trunc[j])))
        env.send(np.stack([_action(env_id, w, min(len(got[w]), steps - 1)) for w in ids.tolist()]), ids)
    for _ in range(n // batch):  # drain what is in flight
        env.recv()
    for w in range(n):
        assert got[w] == expected[w], f"world {w}"


def test_step_async_and_step_wait_equal_step(closing):
    n = 4
    a = gym.make_vec(REACHER, num_envs=n, vectorization_mode="vector_entry_point", envs_per_process=2)
    b = gym.make_vec(REACHER, num_envs=n, vectorization_mode="vector_entry_point", envs_per_process=2)
    closing(a)
    closing(b)
    a.reset(seed=3)
    b.reset(seed=3)
    for t in range(60):
        actions = np.stack([_action(REACHER, w, t) for w in range(n)])
        ra = a.step(actions)
        b.unwrapped.step_async(actions)
        rb = b.unwrapped.step_wait()
        for x, y in zip(ra[:4], rb[:4]):
            np.testing.assert_array_equal(x, y)
        assert sorted(ra[4]) == sorted(rb[4])


def test_async_misuse_is_refused(closing):
    env = gym.make_vec(REACHER, num_envs=4, vectorization_mode="vector_entry_point", envs_per_process=2, batch_size=2)
    closing(env)
    with pytest.raises(StateError, match="before reset"):
        env.send(np.zeros((4, 2), np.float32))
    env.reset(seed=0)
    with pytest.raises(StateError, match="send\\(\\) actions"):
        env.recv()
    env.send(np.zeros((2, 2), np.float32), [0, 1])
    with pytest.raises(StateError, match="in flight"):
        env.send(np.zeros((1, 2), np.float32), [1])
    with pytest.raises(StateError, match="in flight"):
        env.step(np.zeros((4, 2), np.float32))
    with pytest.raises(ValueError, match="distinct"):
        env.send(np.zeros((2, 2), np.float32), [2, 2])
    obs, *_, info = env.recv()
    assert sorted(info["env_id"].tolist()) == [0, 1]
    env.step(np.zeros((4, 2), np.float32))  # nothing in flight: step works again
    with pytest.raises(ValueError, match="batch_size"):
        gym.make_vec(REACHER, num_envs=2, vectorization_mode="vector_entry_point", batch_size=3)
