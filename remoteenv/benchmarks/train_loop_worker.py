"""One contender of the training-loop benchmark: a training process of its own.

Agent side (benchmarks only). ``python -m remoteenv.benchmarks.train_loop_worker
CONTENDER N`` builds the contender's vector env of N Reacher worlds and a
:class:`~remoteenv.benchmarks.harness.ppo_shaped_learner.PPOShapedLearner` beside it,
as a user's training script would (torch's settings as the process has them),
runs one warm-up rollout and update, then serves rounds: each line
``round SECONDS`` on stdin runs whole rollout-and-update iterations until
SECONDS have passed and answers one JSON line on the descriptor given by
``--out-fd`` (steps, wall seconds, where they went, CPU seconds of the process
tree, context switches); ``quit`` closes the env and ends the process.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import numpy as np

from remoteenv.benchmarks.harness.anchors import context_switches, cpu_seconds, make_envpool, process_tree

REMOTE_ID = "remoteenv/Reacher-v0"
GYM_ID = "Reacher-v5"
#: Contender names, in the order a round runs them. ``remoteenv-torch-kept``:
#: remoteenv's vector env with ``torch_threads=None`` (torch's threads as they were);
#: ``remoteenv-os-placed``: with ``place_sims=None`` (the sims left to the OS scheduler);
#: ``remoteenv-neither``: with both (the vector env without either lever);
#: ``process-floor``: the same layout and scene stepping with a bare hand-off
#: (:mod:`remoteenv.benchmarks.harness.process_floor`); ``agent-floor``:
#: remoteenv's vector env and sims under a bare agent end
#: (:mod:`remoteenv.benchmarks.harness.agent_floor`); ``waits-floor``: bare
#: ends that wait as remoteenv's lane does (:mod:`remoteenv.benchmarks.harness.waits_floor`).
CONTENDERS = (
    "remoteenv",
    "EnvPool",
    "SyncVectorEnv",
    "AsyncVectorEnv",
    "remoteenv-torch-kept",
    "remoteenv-os-placed",
    "remoteenv-neither",
    "process-floor",
    "agent-floor",
    "waits-floor",
)
#: Contenders a run has unless asked for others: the anchors and the floor under remoteenv's lane.
DEFAULT_CONTENDERS = (*CONTENDERS[:4], "process-floor")


def make_env(contender: str, num_envs: int) -> Any:
    """The contender's vector env of ``num_envs`` Reacher worlds (seeded with 0 on its first reset)."""
    import gymnasium as gym

    if contender == "remoteenv":
        return gym.make_vec(REMOTE_ID, num_envs, vectorization_mode="vector_entry_point")
    if contender == "remoteenv-torch-kept":
        return gym.make_vec(REMOTE_ID, num_envs, vectorization_mode="vector_entry_point", torch_threads=None)
    if contender == "remoteenv-os-placed":
        return gym.make_vec(REMOTE_ID, num_envs, vectorization_mode="vector_entry_point", place_sims=None)
    if contender == "remoteenv-neither":
        return gym.make_vec(
            REMOTE_ID, num_envs, vectorization_mode="vector_entry_point", torch_threads=None, place_sims=None
        )
    if contender == "EnvPool":
        return make_envpool(GYM_ID, num_envs)
    if contender == "process-floor":
        from remoteenv.benchmarks.harness.process_floor import ProcessFloorVectorEnv

        return ProcessFloorVectorEnv(num_envs)
    if contender == "agent-floor":
        from remoteenv.benchmarks.harness.agent_floor import AgentFloorVectorEnv

        return AgentFloorVectorEnv(num_envs)
    if contender == "waits-floor":
        from remoteenv.benchmarks.harness.waits_floor import WaitsFloorVectorEnv

        return WaitsFloorVectorEnv(num_envs)
    mode = {"SyncVectorEnv": "sync", "AsyncVectorEnv": "async"}[contender]
    return gym.make_vec(GYM_ID, num_envs, vectorization_mode=mode)


class Loop:
    """The contender's env and its learner, and the loop that trains on them."""

    def __init__(self, contender: str, num_envs: int, horizon: int, epochs: int, minibatches: int) -> None:
        # Imported here, not at the top: python -m remoteenv's parser imports this module, and torch
        # would cost every command seconds. Before the env is made, as a trainer imports torch:
        # torch_threads="auto" sets the threads of a torch that is imported.
        from remoteenv.benchmarks.harness.ppo_shaped_learner import PPOShapedLearner

        start = time.perf_counter()
        self.env = make_env(contender, num_envs)
        self.build_s = time.perf_counter() - start
        obs_dim = int(np.prod(self.env.single_observation_space.shape))
        act_dim = int(np.prod(self.env.single_action_space.shape))
        self.learner = PPOShapedLearner(
            obs_dim, act_dim, num_envs, horizon=horizon, epochs=epochs, minibatches=minibatches
        )
        self.num_envs = num_envs
        self.obs = self.env.reset() if contender == "EnvPool" else self.env.reset(seed=0)
        self.obs = self.obs[0]

    def iteration(self, seconds: dict[str, float]) -> int:
        """One rollout of ``horizon`` vector steps and one update; adds the wall
        seconds of each part to ``seconds``; returns the env steps taken."""
        learner, env = self.learner, self.env
        perf = time.perf_counter
        act_s = step_s = 0.0
        steps = 0
        while not learner.full:
            t0 = perf()
            action = learner.act(self.obs)
            t1 = perf()
            self.obs, reward, terminated, truncated, _ = env.step(action)
            t2 = perf()
            learner.record(reward, terminated, truncated)
            act_s += t1 - t0
            step_s += t2 - t1
            steps += self.num_envs
        t0 = perf()
        learner.update(self.obs)
        seconds["update"] += perf() - t0
        seconds["act"] += act_s
        seconds["env_step"] += step_s
        return steps

    def round(self, duration: float) -> dict[str, Any]:
        """Whole iterations until ``duration`` seconds have passed: the round's figures."""
        seconds = {"act": 0.0, "env_step": 0.0, "update": 0.0}
        tree = process_tree()
        own0 = time.process_time()
        cpu0 = cpu_seconds()
        switches0 = context_switches(tree)
        steps = iterations = 0
        start = time.perf_counter()
        while True:
            steps += self.iteration(seconds)
            iterations += 1
            wall = time.perf_counter() - start
            if wall >= duration:
                break
        cpu = cpu_seconds() - cpu0
        own = time.process_time() - own0
        switches = context_switches(tree)
        return {
            "steps": steps,
            "iterations": iterations,
            "wall_s": wall,
            "steps_per_s": steps / wall,
            "cpu_s": cpu,
            "cpu_us_per_step": cpu / steps * 1e6,
            "trainer_cpu_s": own,
            "seconds": seconds,
            "voluntary_switches": switches[0] - switches0[0],
            "involuntary_switches": switches[1] - switches0[1],
            "processes": len(tree),
        }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m remoteenv.benchmarks.train_loop_worker")
    p.add_argument("contender", choices=CONTENDERS)
    p.add_argument("num_envs", type=int)
    p.add_argument("--out-fd", type=int, required=True, help="descriptor the JSON lines are written to")
    p.add_argument("--horizon", type=int, default=128)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--minibatches", type=int, default=4)
    args = p.parse_args(argv)
    out = os.fdopen(args.out_fd, "w", buffering=1)
    import torch

    try:
        loop = Loop(args.contender, args.num_envs, args.horizon, args.epochs, args.minibatches)
    except ImportError as e:
        out.write(json.dumps({"error": f"{args.contender} is not installed: {e}"}) + "\n")
        return 0
    loop.iteration({"act": 0.0, "env_step": 0.0, "update": 0.0})  # warm-up: caches, thread pools, first resets
    out.write(json.dumps({"ready": True, "build_s": loop.build_s, "torch_threads": torch.get_num_threads()}) + "\n")
    try:
        for line in sys.stdin:
            words = line.split()
            if words[:1] == ["round"] and len(words) == 2:
                out.write(json.dumps(loop.round(float(words[1]))) + "\n")
            elif words[:1] == ["quit"]:
                break
    finally:
        loop.env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
