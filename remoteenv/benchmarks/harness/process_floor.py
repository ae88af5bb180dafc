"""The floor under a lock-step vector step with the sims in their own processes.

Benchmarks only (``bench --train-loop``'s ``process-floor`` contender). A
vector env of Reacher worlds laid out as remoteenv lays out the worlds of a
scene whose Python runs per world (``default_envs_per_process(N,
stacked_hooks=False)``: a process per CPU, one physics thread each; with its
children blocking between steps that layout is this contender's fastest,
docs/performance.md "One process, its physics on threads"), the children
made batch work and pinned as ``place_sims="auto"`` does, torch's threads
lowered as ``torch_threads="auto"`` does. Its children run the
scene's own stepping (:class:`~remoteenv.sim.stepping.batch_step.WorldsStepper`:
the stacked hooks, one ``mujoco.batch`` call, the batch and observation
checks) and nothing else around it: the actions and results in one
anonymous shared mapping per child, one byte on a pipe each way per step,
both sides blocking in ``read``. Reacher's 50-step time limit is kept, with
Gymnasium's default autoreset (the step after a truncation resets the world
and returns its first observation, reward 0), the reset done by the scene
in the child. No request or reply is encoded, checked or routed; no infos,
no latency bookkeeping; no failure handling beyond a child's end of file. What remoteenv's step costs above
this contender is its lane's own machinery on both ends; what this costs
above EnvPool is the processes taking turns.

The agent side here and :func:`serve` (the child, ``python -m
remoteenv.benchmarks.harness.process_floor K SEED REQUEST_FD REPLY_FD
REGION_FD``) are in one module because they share the region's layout.
"""

from __future__ import annotations

import mmap
import os
import sys
from typing import Any

import numpy as np

from remoteenv.agent.vector.sim_placement import AUTO, SimPlacement
from remoteenv.agent.vector.torch_threads import TorchThreads
from remoteenv.agent.vector.vector_layout import default_envs_per_process, world_slices
from remoteenv.benchmarks.harness.floor_children import FloorChildren, close_worlds, start_worlds, tick

OBS_DIM, ACT_DIM = 10, 2
_STEP, _DONE = b"s", b"r"


def _blocks(k: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    return {
        "actions": ((k, ACT_DIM), np.dtype(np.float32)),
        "obs": ((k, OBS_DIM), np.dtype(np.float64)),
        "reward": ((k,), np.dtype(np.float64)),
        "terminated": ((k,), np.dtype(np.bool_)),
        "truncated": ((k,), np.dtype(np.bool_)),
    }


def _padded(shape: tuple[int, ...], dt: np.dtype) -> int:
    """Bytes a block takes in the region: each starts on its own 64-byte line."""
    return -(-int(np.prod(shape)) * dt.itemsize // 64) * 64


def region_size(k: int) -> int:
    """Bytes of a child's region."""
    return sum(_padded(shape, dt) for shape, dt in _blocks(k).values())


def region_views(buf: Any, k: int) -> dict[str, np.ndarray]:
    """The region's blocks as arrays over ``buf``."""
    views, offset = {}, 0
    for name, (shape, dt) in _blocks(k).items():
        views[name] = np.ndarray(shape, dt, buffer=buf, offset=offset)
        offset += _padded(shape, dt)
    return views


def serve(k: int, seed: int, request_fd: int, reply_fd: int, region_fd: int) -> None:
    """The child: K Reacher worlds reset with seeds ``seed..seed+K-1``, their
    first observations in the region, then one tick per request byte
    (:func:`~remoteenv.benchmarks.harness.floor_children.tick`)."""
    envs, commands, first = start_worlds(k, seed)
    region = mmap.mmap(region_fd, region_size(k))
    views = region_views(region, k)
    views["obs"][:] = first
    worlds = list(range(k))
    elapsed = 0
    try:
        os.write(reply_fd, _DONE)
        while os.read(request_fd, 1) == _STEP:
            elapsed = tick(commands, views, worlds, elapsed)
            os.write(reply_fd, _DONE)
    finally:
        close_worlds(envs, commands)
        del views
        region.close()


class ProcessFloorVectorEnv:
    """N Reacher worlds in child processes, stepped in lock step through the
    bare hand-off described in the module docstring (``reset`` and ``step`` as
    a Gymnasium vector env's with next-step autoreset, without infos)."""

    def __init__(self, num_envs: int, seed: int = 0) -> None:
        import gymnasium as gym

        self.num_envs = num_envs
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), np.float64)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (ACT_DIM,), np.float32)
        self._slices = world_slices(num_envs, default_envs_per_process(num_envs, stacked_hooks=False))
        self._children = FloorChildren("process-floor")
        self._views: list[dict[str, np.ndarray]] = []
        try:
            for lo, hi in self._slices:
                region = self._children.spawn(__name__, (hi - lo, seed + lo), region_size(hi - lo))
                self._views.append(region_views(region, hi - lo))
            self._children.read_ready(_DONE)
        except BaseException:
            self.close()
            raise
        SimPlacement(AUTO, own_sims=True, real_time=False).apply([p.pid for p in self._procs])
        TorchThreads(AUTO, len(self._procs)).apply()

    @property
    def _procs(self) -> list[Any]:
        """The children's processes."""
        return self._children.procs

    def _gather(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        obs = np.empty((self.num_envs, OBS_DIM))
        reward = np.empty(self.num_envs)
        terminated = np.empty(self.num_envs, dtype=np.bool_)
        truncated = np.empty(self.num_envs, dtype=np.bool_)
        for (lo, hi), fd, views in zip(self._slices, self._children.replies, self._views):
            self._children.read_done(fd, _DONE)
            obs[lo:hi] = views["obs"]
            reward[lo:hi] = views["reward"]
            terminated[lo:hi] = views["terminated"]
            truncated[lo:hi] = views["truncated"]
        return obs, reward, terminated, truncated

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """The observations in the regions: the first ones before any step (the
        children reset their worlds when they started, with the seeds given at
        construction; ``seed`` is ignored, as EnvPool ignores it)."""
        obs = np.concatenate([views["obs"] for views in self._views])
        return obs, {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One tick of every world."""
        for (lo, hi), fd, views in zip(self._slices, self._children.requests, self._views):
            views["actions"][:] = actions[lo:hi]
            os.write(fd, _STEP)
        obs, reward, terminated, truncated = self._gather()
        return obs, reward, terminated, truncated, {}

    def close(self) -> None:
        """Stop the children and wait for them."""
        self._views = []
        self._children.stop()


__all__ = ["ProcessFloorVectorEnv", "region_size", "region_views", "serve"]

if __name__ == "__main__":
    serve(*map(int, sys.argv[1:6]))
