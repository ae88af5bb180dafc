"""Where one batched step's time goes: every stage of the pipeline, in one process.

Benchmarks only (``python -m remoteenv bench --batched --profile``). Runs a
``step_batch`` of N Reacher worlds through the same code a sim and an agent
run, without the processes in between, and times each stage: the sim
decoding the request and checking the actions, the scene's batched hooks,
the physics (one mujoco.batch call where the scene has stacked hooks, else on threads), building and packing the reply; the agent decoding
it and assembling Gymnasium's batch. No episode ends (no time limit; Reacher
never terminates), so no world resets: with Reacher's 50-step limit one
step in 50 also resets every world. What the benchmark's end-to-end figure
adds on top is the transport and the processes' wake-ups.
"""

from __future__ import annotations

import importlib.util
import time
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from remoteenv.agent.vector.autoreset import after_step, plan_ops
from remoteenv.agent.vector.vector_results import ObsBatch, assemble
from remoteenv.sim.stepping.batch_commands import BatchCommands, plain_step_reply
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.wire import protocol
from remoteenv.wire.messages.action_rules import check_actions

STAGES = [
    "agent: plan ops, pack request",
    "sim: decode request, check actions",
    "sim: scene prepare_steps",
    "sim: physics (one mujoco.batch call, or mj_step on threads)",
    "sim: scene post_steps",
    "sim: build and pack reply",
    "agent: decode reply, assemble batch",
]


def reacher_class() -> Any:
    """The shipped Reacher scene's env class (``ReacherEnv``), loaded from its script."""
    import remoteenv

    spec = importlib.util.spec_from_file_location("reacher_scene_profile", remoteenv.scene_path("reacher"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.ReacherEnv


def profile(n: int, steps: int = 500) -> tuple[dict[str, float], dict[str, float]]:
    """Mean microseconds per step of each of :data:`STAGES` for N Reacher worlds
    in one process: wall time, and CPU time of the process (every thread's,
    so the physics on threads counts in full and a preempted stage does not)."""
    reacher = reacher_class()
    envs = [reacher() for _ in range(n)]
    lock = LockStepping(envs)
    commands = BatchCommands(lock.worlds, envs[0].action_space, 0)
    stepper = commands.stepper
    assert stepper is not None
    # The path a sim takes: the stacked hooks over one mujoco.batch where it has one.
    batched = stepper.batched
    hook_envs: Any = stepper._every if batched is not None else envs
    obs_batch = ObsBatch(envs[0].observation_space, n)
    commands.reset_batch({"worlds": list(range(n)), "seeds": list(range(n))}, None, None)
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, size=(n, 2)).astype(np.float32) for _ in range(64)]
    elapsed = np.zeros(n, dtype=np.int64)
    needs_reset = np.zeros(n, dtype=np.bool_)
    totals = np.zeros(len(STAGES))
    cpu_totals = np.zeros(len(STAGES))

    def add_info(infos: dict[str, Any], info: dict[str, Any], i: int) -> dict[str, Any]:
        return infos

    try:
        for t in range(steps + 20):
            stamps = [time.perf_counter()]
            cpu = [time.process_time()]
            ops = plan_ops(AutoresetMode.NEXT_STEP, needs_reset, elapsed, None)
            frame = protocol.pack({"seq": t, "cmd": "step_batch", "ops": ops.tolist(), "actions": actions[t & 63]})
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            msg = protocol.decode_request(frame)
            acts = check_actions(envs[0].action_space, msg["actions"], n)
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            type(envs[0]).prepare_steps(hook_envs, acts)
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            if batched is not None:
                batched.step(None, envs[0].frame_skip)
            else:
                stepper.physics.step(stepper._models, stepper._datas, envs[0].frame_skip)
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            batch = type(envs[0]).post_steps(hook_envs, acts)
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            packed = protocol.pack({"seq": t, "ok": True, **plain_step_reply(batch)})
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            result = protocol.unpack(packed)
            obs, _, terminated, truncated, _ = assemble({0: result}, [(0, n)], obs_batch, add_info)
            _, elapsed, needs_reset = after_step(AutoresetMode.NEXT_STEP, ops, terminated, truncated, elapsed, None)
            stamps.append(time.perf_counter())
            cpu.append(time.process_time())
            if t >= 20:
                totals += np.diff(stamps)
                cpu_totals += np.diff(cpu)
    finally:
        commands.close()
        for env in envs:
            env.close()
    wall = {stage: float(total / steps * 1e6) for stage, total in zip(STAGES, totals)}
    return wall, {stage: float(total / steps * 1e6) for stage, total in zip(STAGES, cpu_totals)}


__all__ = ["STAGES", "profile", "reacher_class"]
