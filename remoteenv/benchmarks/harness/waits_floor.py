"""The floor under remoteenv's lane with its own waits: bare ends that wait as the lane does.

Benchmarks only (``bench --train-loop``'s ``waits-floor`` contender). Like
``process-floor`` (:mod:`remoteenv.benchmarks.harness.process_floor`) a bare
hand-off of Reacher worlds through one shared mapping per child process, but
laid out and waiting the way remoteenv's lock-step lane does:

- remoteenv's default layout of N worlds (:func:`default_envs_per_process`
  for a scene with stacked hooks, its physics threads from
  :func:`layout_threads`: one process of every world on two threads at
  N >= 9 on two CPUs), placed as ``place_sims="auto"`` places sims, torch's
  threads as ``torch_threads="auto"`` sets them (its update's threads too);
- the region's doorbell (:mod:`remoteenv.wire.shared_memory.doorbell`, the
  project's own): a child waits hot for the next request for up to
  :data:`~remoteenv.sim.serving.sim_server.SIM_SPIN_S`, stopping early when
  the agent says its caller began its update (``AGENT_AWAY``), then blocks
  on its pipe; the agent blocks after posting, asks a lone child for a
  heads-up once the physics is done and then waits hot for the reply, at most
  :data:`~remoteenv.agent.connection.pipe_connection.HEADS_UP_WAIT_S`.

A child runs the scene's own stepping
(:class:`~remoteenv.sim.stepping.batch_step.WorldsStepper`) and nothing else
around it, and keeps Reacher's time limit with next-step autoreset as
``process-floor`` does. No request or reply is encoded, checked or routed;
no ops, no infos, no latency bookkeeping, no tamper checks. So this
contender against ``remoteenv`` measures what remoteenv's lane costs beyond
its wait design (the two ends' own work), and against ``process-floor``
what that design gains over blocking.

The agent side and :func:`serve` (the child, ``python -m
remoteenv.benchmarks.harness.waits_floor K SEED THREADS REQUEST_FD REPLY_FD
REGION_FD``) are in one module because they share the region's layout.
"""

from __future__ import annotations

import mmap
import os
import sys
import time
from typing import Any

import numpy as np

from remoteenv.agent.connection.pipe_connection import HEADS_UP_WAIT_S
from remoteenv.agent.vector.sim_placement import AUTO, SimPlacement
from remoteenv.agent.vector.torch_threads import TorchThreads
from remoteenv.agent.vector.vector_layout import default_envs_per_process, layout_threads, world_slices
from remoteenv.benchmarks.harness.floor_children import QUIT, FloorChildren, close_worlds, start_worlds, tick
from remoteenv.benchmarks.harness.process_floor import ACT_DIM, OBS_DIM, region_size, region_views
from remoteenv.wire.shared_memory.doorbell import SILENT, Doorbell

#: Bytes before the blocks of a child's region: the doorbell's 16 ``<i8`` words.
HEADER_BYTES = 128
_DONE, _SOON, _STEP = b"r", b"h", b"s"


def _region_bytes(k: int) -> int:
    """Bytes of a child's region: the header, then the blocks of ``process-floor``'s layout."""
    return HEADER_BYTES + region_size(k)


def _parts(region: mmap.mmap, k: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A child's region: its header words and its blocks."""
    header = np.ndarray((16,), "<i8", buffer=region, offset=0)
    return header, region_views(memoryview(region)[HEADER_BYTES:], k)


def serve(k: int, seed: int, threads: int, request_fd: int, reply_fd: int, region_fd: int) -> None:
    """The child: K Reacher worlds reset with seeds ``seed..seed+K-1`` on
    ``threads`` physics threads, their first observations in the region, then
    one tick per request posted on the doorbell (a reset of every world on
    the tick after their time limit, as ``process-floor``'s children do)."""
    from remoteenv.sim.serving.sim_server import SIM_SPIN_S

    envs, commands, first = start_worlds(k, seed, threads)
    region = mmap.mmap(region_fd, _region_bytes(k))
    header, views = _parts(region, k)
    bell = Doorbell(header)
    views["obs"][:] = first
    try:
        os.write(reply_fd, _DONE)
        _answer_requests(bell, views, commands, request_fd, reply_fd, SIM_SPIN_S)
    finally:
        close_worlds(envs, commands)
        del views, header, bell  # the region's views, before it is unmapped
        region.close()


def _answer_requests(
    bell: Doorbell, views: dict[str, np.ndarray], commands: Any, request_fd: int, reply_fd: int, spin_s: float
) -> None:
    """The child's loop: wait for each request (hot for up to ``spin_s``,
    then blocking), tick every world, answer; until the agent quits."""
    worlds = list(range(len(views["reward"])))
    perf, yield_cpu = time.perf_counter, os.sched_yield

    def heads_up() -> None:
        if bell.agent_wants_heads_up():
            os.write(reply_fd, _SOON)

    bell.sim_watches()
    elapsed = served = 0
    while True:
        seq = bell.posted(served)
        until = perf() + spin_s
        while not seq and not bell.agent_away() and perf() < until:
            yield_cpu()
            seq = bell.posted(served)
        while not seq:
            seq = bell.sim_sleeps(served)
            if seq:
                break
            got = os.read(request_fd, 64)  # a ring, or one left from a request found awake
            if not got or QUIT in got:
                return
            bell.sim_watches()
            seq = bell.posted(served)
        served = seq
        elapsed = tick(commands, views, worlds, elapsed, heads_up)
        if bell.reply(seq, 0):
            os.write(reply_fd, _DONE)


class WaitsFloorVectorEnv:
    """N Reacher worlds in child processes, stepped in lock step through the
    bare ends described in the module docstring (``reset`` and ``step`` as a
    Gymnasium vector env's with next-step autoreset, without infos)."""

    def __init__(self, num_envs: int, seed: int = 0) -> None:
        import gymnasium as gym

        if not SILENT:
            raise RuntimeError("waits-floor reads the doorbell's sequence words, which needs an x86-64 CPU")
        self.num_envs = num_envs
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), np.float64)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (ACT_DIM,), np.float32)
        k = default_envs_per_process(num_envs)
        self._slices = world_slices(num_envs, k)
        self.threads = layout_threads(num_envs, k) or 1
        self._children = FloorChildren("waits-floor")
        self._lanes: list[tuple[int, int, int, int, Doorbell, dict[str, np.ndarray]]] = []
        self._seq = 0
        try:
            for lo, hi in self._slices:
                region = self._children.spawn(__name__, (hi - lo, seed + lo, self.threads), _region_bytes(hi - lo))
                header, views = _parts(region, hi - lo)
                p = len(self._lanes)
                ends = self._children.requests[p], self._children.replies[p]
                self._lanes.append((lo, hi, *ends, Doorbell(header), views))
            self._children.read_ready(_DONE)
        except BaseException:
            self.close()
            raise
        SimPlacement(AUTO, own_sims=True, real_time=False).apply([p.pid for p in self._procs])
        self._torch = TorchThreads(AUTO, len(self._procs) * self.threads, away=self._away)
        self._torch.apply()

    @property
    def _procs(self) -> list[Any]:
        """The children's processes."""
        return self._children.procs

    def _away(self) -> None:
        """The caller's update begins (torch's update threads say so): the children stop waiting hot."""
        for *_, bell, _views in self._lanes:
            bell.away()

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """The observations in the regions: the first ones before any step (the
        children reset their worlds when they started, with the seeds given at
        construction; ``seed`` is ignored, as EnvPool ignores it)."""
        return np.concatenate([views["obs"] for *_, views in self._lanes]), {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One tick of every world."""
        self._torch.step_starts()
        self._seq += 1
        seq = self._seq
        for lo, hi, request_fd, _, bell, views in self._lanes:
            views["actions"][:] = actions[lo:hi]
            if bell.post(seq, hi - lo, False):
                os.write(request_fd, _STEP)
        heads_up = len(self._lanes) == 1
        perf, yield_cpu = time.perf_counter, os.sched_yield
        obs = np.empty((self.num_envs, OBS_DIM))
        reward = np.empty(self.num_envs)
        terminated = np.empty(self.num_envs, dtype=np.bool_)
        truncated = np.empty(self.num_envs, dtype=np.bool_)
        for lo, hi, _, reply_fd, bell, views in self._lanes:
            while not bell.answered(seq):
                if not bell.agent_sleeps(seq, heads_up=heads_up):
                    break
                got = os.read(reply_fd, 64)
                bell.agent_wakes()
                if not got:
                    raise RuntimeError("a waits-floor child ended; its error is above")
                if _SOON in got:
                    until = perf() + HEADS_UP_WAIT_S
                    while not bell.answered(seq) and perf() < until:
                        yield_cpu()
            obs[lo:hi] = views["obs"]
            reward[lo:hi] = views["reward"]
            terminated[lo:hi] = views["terminated"]
            truncated[lo:hi] = views["truncated"]
        self._torch.step_returns()
        return obs, reward, terminated, truncated, {}

    def close(self) -> None:
        """Stop the children and wait for them."""
        torch_threads = getattr(self, "_torch", None)
        if torch_threads is not None:
            torch_threads.interrupted()
        self._lanes = []
        self._children.stop()


__all__ = ["WaitsFloorVectorEnv", "serve"]

if __name__ == "__main__":
    serve(*map(int, sys.argv[1:7]))
