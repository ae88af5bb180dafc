"""What the sim's reply to a step that starts episodes costs: from the arrays, or world by world.

Benchmarks only (``python -m remoteenv bench --batched --profile``, after the
stage table). A vector step in which some worlds start an episode while the
others step gets its reply built from the stepped worlds' arrays
(:func:`~remoteenv.sim.stepping.autoreset_reply.autoreset_reply`) or, for
results that are not arrays, world by world
(:meth:`BatchCommands._reply <remoteenv.sim.stepping.batch_commands.BatchCommands._reply>`).
Both give the same bytes (checked here). This times both on the same step
of N Reacher worlds in one process, building and packing the reply only:
the physics and the worlds' resets are done once, before the timing (the
started worlds' results are reused), so the figure is what the encoding
costs, in alternating blocks.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from remoteenv.benchmarks.harness.step_profile import reacher_class
from remoteenv.sim.stepping.autoreset_reply import autoreset_reply
from remoteenv.sim.stepping.batch_commands import BatchCommands, _per_world_results
from remoteenv.sim.stepping.lock_step import LockStepping
from remoteenv.wire import protocol
from remoteenv.wire.protocol import OP_RESET, OP_STEP, OP_STEP_RESET

#: The steps timed: which op the one world that starts an episode has, the others stepping.
CASES = {
    "next-step autoreset: one world resets": OP_RESET,
    "same-step autoreset: one episode ends": OP_STEP_RESET,
}


def reply_profile(n: int, blocks: int = 20, per_block: int = 50) -> dict[str, tuple[float, float]]:
    """Median microseconds to build and pack the reply of each of :data:`CASES`
    for N Reacher worlds (N >= 2): ``(world by world, from the arrays)``."""
    reacher = reacher_class()
    envs = [reacher() for _ in range(n)]
    commands = BatchCommands(LockStepping(envs).worlds, envs[0].action_space, 0)
    stepper = commands.stepper
    assert stepper is not None
    worlds = list(range(n))
    actions = np.random.default_rng(0).uniform(-1, 1, size=(n, 2)).astype(np.float32)
    out: dict[str, tuple[float, float]] = {}
    try:
        commands.reset_batch({"worlds": worlds, "seeds": worlds}, None, None)
        for case, op in CASES.items():
            ops = [OP_STEP] * n
            ops[n // 2] = op
            stepped = [j for j in worlds if ops[j] != OP_RESET]
            batch = stepper.step(stepped, actions[stepped])
            started = commands._start([n // 2], [None], None)
            # Both paths reuse the one start made above: the timing is the reply's alone.
            commands._start_at = lambda _worlds, _starts: started  # type: ignore[method-assign,assignment]

            def per_world(ops: list[int] = ops, stepped: list[int] = stepped, batch: Any = batch) -> bytes:
                return protocol.pack(commands._reply(ops, worlds, _per_world_results(batch, stepped, n)))

            def arrays(ops: list[int] = ops, stepped: list[int] = stepped, batch: Any = batch) -> bytes:
                reply = autoreset_reply(batch, ops, stepped, lambda _starts: started)
                assert reply is not None, "Reacher's results are arrays"
                return protocol.pack(reply)

            if per_world() != arrays():
                raise AssertionError(f"the two replies differ for {case!r}")
            times: dict[str, list[float]] = {"per world": [], "arrays": []}
            for _ in range(blocks):
                for name, build in (("per world", per_world), ("arrays", arrays)):
                    t0 = time.perf_counter()
                    for _ in range(per_block):
                        build()
                    times[name].append((time.perf_counter() - t0) / per_block)
            del commands._start_at
            out[case] = (float(np.median(times["per world"]) * 1e6), float(np.median(times["arrays"]) * 1e6))
    finally:
        commands.close()
        for env in envs:
            env.close()
    return out


__all__ = ["CASES", "reply_profile"]
