"""``python -m remoteenv demo <scene>``: launch a sim, run a controller, print returns."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from remoteenv import SHIPPED_SCENES as SCENES


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "demo",
        help="run a shipped scene with a simple controller",
        description="Launch a scene's sim process, drive it with a simple controller "
        "(cartpole: LQR balance, reacher: reaching controller, hexapod: tripod gait) "
        "and print each episode's return, length and steps/s (and, for scenes that "
        "report info['x_position'], the distance moved along x).",
    )
    p.add_argument("scene", choices=sorted(SCENES), help="which shipped scene")
    p.add_argument("--episodes", type=int, default=3, help="episodes to run (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first reset (default 0)")
    p.add_argument("--continuous", action="store_true", help="cartpole: Box(-1, 1) action instead of Discrete(2)")
    p.add_argument("--random", action="store_true", help="random actions instead of the controller")
    p.add_argument(
        "--transport",
        choices=["pipe", "ipc", "tcp"],
        default="pipe",
        help="how the env talks to its sim: the local pipe (default) or ZeroMQ over ipc or tcp",
    )
    p.add_argument(
        "--record",
        metavar="DIR",
        default=None,
        help="render offscreen and write one mp4 per episode into DIR "
        "(gymnasium.wrappers.RecordVideo; needs moviepy, the [video] extra)",
    )
    p.add_argument(
        "--real-time",
        action="store_true",
        help="run the sim on a paced wall clock: it keeps going while the agent thinks",
    )
    p.add_argument(
        "--real-time-factor",
        type=float,
        default=1.0,
        help="with --real-time: simulated seconds per wall-clock second (default 1.0)",
    )
    p.add_argument(
        "--think-ms", type=float, default=0.0, help="the agent sleeps this many ms before each action (default 0)"
    )
    p.add_argument(
        "--action-delay",
        type=int,
        default=0,
        help="lock-step: each action takes effect this many ticks later (default 0)",
    )
    p.set_defaults(run=run)


#: A demo policy: ``policy(obs, t) -> action`` where ``t`` is the simulated
#: time since the episode's reset (s), for controllers that need a phase.
Policy = Callable[[Any, float], Any]


def make_policy(scene: str, env: gym.Env, random: bool) -> Policy:
    """The demo's controller for ``scene`` (or random actions)."""
    from remoteenv import controllers

    if random:
        return lambda obs, t: env.action_space.sample()
    if scene == "hexapod":
        return controllers.hexapod_tripod
    if scene == "reacher":
        return lambda obs, t: controllers.reacher_reach(obs)
    if isinstance(env.action_space, gym.spaces.Discrete):
        return lambda obs, t: controllers.cartpole_discrete(obs)
    return lambda obs, t: controllers.cartpole_continuous(obs)


def make_env(args: argparse.Namespace) -> gym.Env:
    kwargs: dict[str, Any] = {"transport": args.transport}
    if args.scene == "cartpole":
        kwargs["continuous"] = args.continuous
    if getattr(args, "real_time", False):
        kwargs.update(real_time=True, real_time_factor=args.real_time_factor)
    if getattr(args, "action_delay", 0):
        kwargs["action_delay"] = args.action_delay
    if getattr(args, "record", None):
        kwargs["render_mode"] = "rgb_array"
        env = gym.make(SCENES[args.scene], **kwargs)
        return gym.wrappers.RecordVideo(env, args.record, episode_trigger=lambda episode: True, name_prefix=args.scene)
    return gym.make(SCENES[args.scene], **kwargs)


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    env = make_env(args)
    try:
        policy = make_policy(args.scene, env, args.random)
        env.action_space.seed(args.seed)
        obs, info = env.reset(seed=args.seed)
        remote: Any = env.unwrapped  # the OpenAIRemoteEnv under gym.make's wrappers
        dt = float(remote.dt)
        print(
            f"{env.spec.id if env.spec else args.scene}: sim pid {remote.pid}, "
            f"obs {env.observation_space}, action {env.action_space}; "
            f"make + first reset {time.perf_counter() - t0:.3f} s"
        )
        total_steps, total_time = 0, 0.0
        for episode in range(args.episodes):
            if episode:
                obs, info = env.reset()
            x_start = info.get("x_position")
            ret, steps, done, t = 0.0, 0, False, 0.0
            start = time.perf_counter()
            while not done:
                if args.think_ms > 0:
                    time.sleep(args.think_ms / 1e3)
                obs, reward, terminated, truncated, info = env.step(policy(obs, t))
                # Real-time replies say how many control ticks passed; lock-step is one.
                t += dt * int(info.get("ticks_elapsed", 1))
                ret += float(reward)
                steps += 1
                done = terminated or truncated
            elapsed = time.perf_counter() - start
            total_steps += steps
            total_time += elapsed
            end = "terminated" if terminated else "truncated"
            moved = ""
            if x_start is not None and "x_position" in info:
                moved = f"  x moved {float(info['x_position']) - float(x_start):+.3f} m"
            print(
                f"episode {episode}: return {ret:9.3f}  steps {steps:4d} ({end})  {steps / elapsed:8.0f} steps/s{moved}"
            )
        print(f"all episodes: {total_steps} steps, {total_steps / max(total_time, 1e-9):.0f} steps/s")
        if args.real_time or args.action_delay or args.think_ms > 0:
            print("latency stats (env.unwrapped.latency_stats):")
            print(remote.latency_stats.format())
    finally:
        env.close()
    return 0
