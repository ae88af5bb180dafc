"""A stalled real-time sim never applies an action in the past.

The test stops its own sim (``SIGSTOP`` of the sim process its env launched)
while the agent thinks, and continues it (``SIGCONT``) some ticks later. An
action sent during the stall cannot be read before the stall ends, so it
must take effect at a substep whose deadline is at or after that; the
overdue substeps the sim then runs back to back keep the previous action.

What is asserted holds whatever the scheduler does, so it is asserted
exactly (no timing bound; a loaded host only makes stalls longer):

- the latency of a step is never below the agent's think time (from
  receiving the previous reply to sending), nor below the stall;
- in ``fixed_step`` the latency equals the ticks the step lasted, which
  are at least the stall's whole ticks, and the step is ``late``;
- the reward is the ticks elapsed (CartPole: +1 per tick);
- no action acts at a substep whose deadline preceded its sending. The
  agent does not know the clock's start ``t0``, but every reply bounds it
  from above (a reply about substep ``n`` leaves once boundary ``n`` is
  processed, never before its deadline ``t0 + n * period``; the reset's
  reply leaves after ``t0`` is read), so a step is counted as acting before
  it was sent only when it certainly did; an earlier action by less than
  the fastest reply's transit would go unseen.
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from remoteenv.controllers import cartpole_continuous

ENV_ID = "remoteenv/CartPole-v0"


def make(mode: str) -> gym.Env:
    return gym.make(ENV_ID, continuous=True, real_time=True, real_time_mode=mode, max_episode_steps=-1)


class Stall:
    """Stop ``pid`` from clock time ``start`` to ``end`` (``time.monotonic``), on a thread."""

    def __init__(self, pid: int, start: float, end: float) -> None:
        self.pid, self.start, self.end = pid, start, end
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        sleep_until(self.start)
        os.kill(self.pid, signal.SIGSTOP)
        sleep_until(self.end)
        os.kill(self.pid, signal.SIGCONT)

    def finish(self) -> None:
        self.thread.join()
        os.kill(self.pid, signal.SIGCONT)  # never leave the sim stopped


def sleep_until(t: float) -> None:
    while (left := t - time.monotonic()) > 0:
        time.sleep(left)


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_a_sim_stopped_while_the_agent_thinks_applies_the_action_after_the_stall(mode):
    env = make(mode)
    try:
        dt = env.unwrapped.dt
        frame_skip = env.unwrapped.handshake.frame_skip
        pid = env.unwrapped.pid
        obs, _ = env.reset(seed=3)
        for _ in range(3):
            obs, *_ = env.step(cartpole_continuous(obs))
        for stall_ticks, think_ticks in [(3.0, 1.25), (2.5, 0.5), (4.0, 0.1)]:
            received = time.monotonic()
            stall = Stall(pid, received, received + stall_ticks * dt)
            try:
                action = cartpole_continuous(obs)
                sleep_until(received + think_ticks * dt)
                sent = time.monotonic()
                obs, reward, terminated, truncated, info = env.step(action)
            finally:
                stall.finish()
            think = sent - received
            assert info["action_substep"] is not None and not terminated
            assert info["latency_s"] >= think - 1e-9, info
            assert info["latency_s"] >= stall_ticks * dt - 1e-9, info
            assert info["ticks_elapsed"] >= math.floor(stall_ticks) and info["late"], info
            assert reward == float(info["ticks_elapsed"])
            if mode == "fixed_step":
                assert info["latency_ticks"] == info["ticks_elapsed"]
                assert info["action_substep"] == info["substep"] and info["substep"] % frame_skip == 0
            for _ in range(3):  # back in step
                obs, *_ = env.step(cartpole_continuous(obs))
    finally:
        env.close()


def run_fuzz(mode: str, steps: int, seed: int) -> dict[str, Any]:
    """``steps`` steps with random think times and random stalls; per episode the
    send and receive times with each step's info, and the reset's reply time."""
    rng = np.random.default_rng(seed)
    env = make(mode)
    episodes: list[dict[str, Any]] = []
    try:
        dt = env.unwrapped.dt
        pid = env.unwrapped.pid
        period = dt / env.unwrapped.handshake.frame_skip
        obs, _ = env.reset(seed=seed)
        received = time.monotonic()
        episode: dict[str, Any] = {"reset_received": received, "steps": []}
        for _ in range(steps):
            think = rng.uniform(0.0, 2.0) * dt
            stall = None
            if rng.random() < 0.6:  # a stall from before to after the sending, of 0..5 ticks
                start = received + rng.uniform(0.0, think + dt)
                stall = Stall(pid, start, start + rng.uniform(0.0, 5.0) * dt)
            try:
                action = cartpole_continuous(obs)
                sleep_until(received + think)
                sent = time.monotonic()
                obs, reward, terminated, truncated, info = env.step(action)
            finally:
                if stall is not None:
                    stall.finish()
            now = time.monotonic()
            episode["steps"].append({"sent": sent, "think": sent - received, "received": now, "info": info})
            received = now
            if terminated or truncated:
                episodes.append(episode)
                obs, _ = env.reset()
                received = time.monotonic()
                episode = {"reset_received": received, "steps": []}
        if episode["steps"]:
            episodes.append(episode)
    finally:
        env.close()
    return {"period": period, "episodes": episodes}


@pytest.mark.parametrize("mode", ["elastic", "fixed_step"])
def test_fuzz_stalls_and_think_times_never_act_before_the_action_was_sent(mode):
    run = run_fuzz(mode, steps=60, seed=7 if mode == "elastic" else 8)
    period = run["period"]
    early, below = [], []
    for episode in run["episodes"]:
        steps = episode["steps"]
        t0_bound = min([episode["reset_received"], *(s["received"] - s["info"]["substep"] * period for s in steps)])
        for j, s in enumerate(steps):
            info = s["info"]
            if info["action_substep"] is None:  # the episode ended first
                continue
            if t0_bound + info["action_substep"] * period < s["sent"]:
                early.append((j, 1e3 * (s["sent"] - t0_bound - info["action_substep"] * period)))
            if info["latency_s"] < s["think"] - 1e-9:
                below.append((j, info["latency_s"], s["think"]))
            if mode == "fixed_step":
                assert info["latency_ticks"] == info["ticks_elapsed"]
            assert info["late"] == (info["ticks_elapsed"] > 1)
    assert sum(len(e["steps"]) for e in run["episodes"]) == 60
    assert early == [], f"steps that acted before they were sent (step, ms early): {early}"
    assert below == [], f"steps whose latency is below the think time (step, latency s, think s): {below}"
