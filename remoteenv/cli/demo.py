"""``python -m remoteenv demo ID_OR_SCENE``: launch a sim, run a controller, print returns.

``ID_OR_SCENE`` is a shipped scene's name (``cartpole``, ``reacher``,
``hexapod``: each has its own controller), any registered Gymnasium id that
remoteenv serves (``module:id`` imports the module first) or the path of a
scene script. Other scenes run random actions, unless their scene script
defines ``demo_policy(obs, t) -> action`` (``t``: simulated seconds since the
reset), which the demo then loads and uses.

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import os
import sys
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from remoteenv import SHIPPED_SCENES as SCENES
from remoteenv.cli.arguments import (
    json_map,
    non_negative_int,
    non_negative_number,
    positive_factor,
    positive_int,
    seed_int,
)
from remoteenv.cli.optional import require
from remoteenv.remote_env import OpenAIRemoteEnv

#: Steps per episode for a scene script run without a registered time limit.
DEFAULT_MAX_STEPS = 1000


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "demo",
        help="run a scene (shipped, registered id or scene script) with a controller or random actions",
        description="Launch a scene's sim process, drive it with a simple controller "
        "(cartpole: LQR balance, reacher: reaching controller, hexapod: tripod gait; "
        "another scene: its script's demo_policy(obs, t) if it defines one, else random "
        "actions) and print each episode's return, length and steps/s (and, for scenes "
        "that report info['x_position'], the distance moved along x).",
    )
    p.add_argument(
        "scene",
        metavar="ID_OR_SCENE",
        help=f"a shipped scene ({', '.join(sorted(SCENES))}), a registered env id "
        "(e.g. remoteenv/Reacher-v0 or mypkg:mypkg/MyScene-v0) or the path of a scene script",
    )
    p.add_argument(
        "--max-steps",
        type=positive_int,
        default=None,
        help=f"truncate episodes after this many steps (default: the id's limit; {DEFAULT_MAX_STEPS} for a script)",
    )
    p.add_argument(
        "--viewer",
        action="store_true",
        help="show the sim in MuJoCo's viewer window (render_mode='human'; needs a display)",
    )
    p.add_argument("--episodes", type=positive_int, default=3, help="episodes to run (default 3)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the first reset (default 0)")
    p.add_argument("--continuous", action="store_true", help="cartpole: Box(-1, 1) action instead of Discrete(2)")
    p.add_argument("--random", action="store_true", help="random actions instead of the controller")
    p.add_argument(
        "--env-kwargs",
        metavar="JSON",
        default=None,
        help='keyword arguments of the env as a JSON map, e.g. \'{"obs_mode": "pixels", "image_size": 84}\' '
        "(a camera observation: the controllers then read its 'state' part, or act at random on pixels alone)",
    )
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
        type=positive_factor,
        default=1.0,
        help="with --real-time: simulated seconds per wall-clock second (default 1.0)",
    )
    p.add_argument(
        "--think-ms",
        type=non_negative_number,
        default=0.0,
        help="the agent sleeps this many ms before each action (default 0)",
    )
    p.add_argument(
        "--action-delay",
        type=non_negative_int,
        default=0,
        help="lock-step: each action takes effect this many ticks later (default 0)",
    )
    p.set_defaults(run=run)


#: A demo policy: ``policy(obs, t) -> action`` where ``t`` is the simulated
#: time since the episode's reset (s), for controllers that need a phase.
Policy = Callable[[Any, float], Any]


def scene_script(target: str) -> str | None:
    """The scene script behind a demo target (a path, or an id's ``scene`` kwarg)."""
    if os.path.isfile(target):
        return os.path.abspath(target)
    try:
        spec = gym.spec(target.rsplit(":", 1)[-1])  # "module:id": make() has imported the module
    except gym.error.Error:
        return None
    scene = (spec.kwargs or {}).get("scene")
    return os.fspath(scene) if scene else None


def script_policy(path: str | None) -> Policy | None:
    """The ``demo_policy`` a scene script defines (loaded without running its
    ``__main__`` block), or None if it defines none."""
    if path is None:
        return None
    from remoteenv.wire.files.file_reads import read_text

    try:
        tree = ast.parse(read_text(path, MAX_SCRIPT_BYTES, what="scene script"), filename=path)
    except (OSError, SyntaxError, ValueError):
        return None
    if not any(isinstance(n, ast.FunctionDef) and n.name == "demo_policy" for n in tree.body):
        return None
    spec = importlib.util.spec_from_file_location("_remoteenv_demo_scene", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.demo_policy


def make_policy(scene: str, env: gym.Env, random: bool) -> Policy:
    """The demo's controller for ``scene`` (or random actions)."""
    from remoteenv.scene_controllers.cartpole import cartpole_continuous, cartpole_discrete
    from remoteenv.scene_controllers.hexapod import hexapod_tripod
    from remoteenv.scene_controllers.reacher import reacher_reach

    if random:
        return lambda obs, t: env.action_space.sample()
    if scene not in SCENES:
        own = script_policy(scene_script(scene))
        return own if own is not None else (lambda obs, t: env.action_space.sample())
    if scene == "hexapod":
        return hexapod_tripod
    if scene == "reacher":
        return lambda obs, t: reacher_reach(obs)
    if isinstance(env.action_space, gym.spaces.Discrete):
        return lambda obs, t: cartpole_discrete(obs)
    return lambda obs, t: cartpole_continuous(obs)


def on_state(policy: Policy, env: gym.Env) -> Policy:
    """``policy`` for a camera observation: a Dict's ``"state"`` part goes to
    the controller; pixels alone get random actions (no controller reads images)."""
    space = env.observation_space
    if isinstance(space, gym.spaces.Dict) and "state" in space.spaces:
        return lambda obs, t: policy(obs["state"], t)
    if isinstance(space, gym.spaces.Box) and space.dtype == "uint8" and len(space.shape) == 3:
        return lambda obs, t: env.action_space.sample()
    return policy


def has_display() -> bool:
    """Whether a window can be opened (an X11 or Wayland display is set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def make_env(args: argparse.Namespace) -> gym.Env:
    kwargs: dict[str, Any] = {"transport": args.transport}
    if args.scene == "cartpole":
        kwargs["continuous"] = args.continuous
    if getattr(args, "real_time", False):
        kwargs.update(real_time=True, real_time_factor=args.real_time_factor)
    if getattr(args, "action_delay", 0):
        kwargs["action_delay"] = args.action_delay
    env_kwargs = getattr(args, "env_kwargs", None)
    if env_kwargs:
        kwargs.update(json_map(env_kwargs, "--env-kwargs"))
    if getattr(args, "viewer", False):
        kwargs["render_mode"] = "human"
    record = getattr(args, "record", None)
    if record:
        require_moviepy()
        kwargs["render_mode"] = "rgb_array"
    env = _make(args.scene, getattr(args, "max_steps", None), kwargs)
    if record:
        prefix = os.path.splitext(os.path.basename(args.scene))[0].replace("/", "-")
        return gym.wrappers.RecordVideo(env, record, episode_trigger=lambda episode: True, name_prefix=prefix)
    return env


def require_moviepy() -> None:
    """Exit with the install hint unless moviepy (``--record``'s video writer) imports."""
    try:
        import moviepy  # noqa: F401
    except ImportError:
        raise SystemExit(
            "demo: --record writes videos with moviepy, which is not installed: pip install 'remoteenv[video]'"
        ) from None


def _make(target: str, max_steps: int | None, kwargs: dict[str, Any]) -> gym.Env:
    """The env of a demo target: a shipped scene, a registered id or a scene script."""
    if target in SCENES:
        return gym.make(SCENES[target], max_episode_steps=max_steps, **kwargs)
    if os.path.isfile(target):
        check_scene_script(target)
        env: gym.Env = OpenAIRemoteEnv(target, **kwargs)
        return gym.wrappers.TimeLimit(env, max_steps or DEFAULT_MAX_STEPS)
    try:
        return gym.make(target, max_episode_steps=max_steps, **kwargs)
    except (gym.error.Error, ModuleNotFoundError) as exc:  # "module:id" whose module is not there
        raise SystemExit(
            f"demo: {target!r} is neither a shipped scene ({', '.join(sorted(SCENES))}), a scene "
            f"script nor a registered id ({exc}); {id_hint(target)}"
        ) from None


#: Largest scene script the demo reads to check it.
MAX_SCRIPT_BYTES = 4 << 20


def check_scene_script(path: str) -> None:
    """Exit with one line unless ``path`` is a Python file that serves a scene
    (calls ``run_scene``), before any sim is started for it."""
    from remoteenv.wire.files.file_reads import read_text

    if not path.endswith(".py"):
        raise SystemExit(f"demo: {path[:200]!r} is not a Python file; a scene script ends in .py")
    try:
        tree = ast.parse(read_text(path, MAX_SCRIPT_BYTES, what="scene script"), filename=path)
    except (OSError, ValueError, SyntaxError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise SystemExit(f"demo: cannot read {path[:200]!r} as a scene script: {first}") from None
    calls = {
        node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", None)
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
    }
    if not calls & {"run_scene", "RemoteControlledAgent"}:
        raise SystemExit(
            f"demo: {path[:200]!r} is not a scene script: it never calls run_scene(YourEnv) "
            "(see remoteenv.sim.run_scene, or python -m remoteenv new-scene)"
        )


def id_hint(target: str) -> str:
    """What to do about an id ``gym.make`` did not find (``module:`` prefix or not)."""
    if ":" not in target:
        return "for a package's id use 'package:namespace/Name-v0' (the package is imported first)"
    module = target.split(":", 1)[0]
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        spec = None
    if spec is None:
        return f"{module!r} is not importable here: install it (pip install -e DIR) or run from where it is"
    if spec.origin in (None, "namespace"):
        where = ", ".join(spec.submodule_search_locations or [])
        return (
            f"{module!r} imports as an empty namespace package from {where}: a folder of that name "
            "(e.g. the package's project folder) hides the installed package; run from another "
            "directory, or give the package a src layout (as new-scene writes it)"
        )
    return f"importing {module!r} ({spec.origin}) did not register that id; check the id in its gymnasium.register"


def run(args: argparse.Namespace) -> int:
    if args.viewer and not has_display():
        print("demo: --viewer needs a display (DISPLAY or WAYLAND_DISPLAY); use --record DIR instead", file=sys.stderr)
        return 2
    if args.record:
        require("moviepy", "demo --record")
    t0 = time.perf_counter()
    env = make_env(args)
    try:
        shipped = {env_id: name for name, env_id in SCENES.items()}.get(args.scene, args.scene)
        policy = on_state(make_policy(shipped, env, args.random), env)
        env.action_space.seed(args.seed)
        obs, info = env.reset(seed=args.seed)
        remote: Any = env.unwrapped  # the OpenAIRemoteEnv under gym.make's wrappers
        dt = float(getattr(remote, "dt", 0.0) or 0.0)  # an in-process env may not say
        print(
            f"{env.spec.id if env.spec else args.scene}: sim pid {getattr(remote, 'pid', None)}, "
            f"obs {env.observation_space}, action {env.action_space}; "
            + (f"env kwargs {json_map(args.env_kwargs, '--env-kwargs')}; " if args.env_kwargs else "")
            + f"make + first reset {time.perf_counter() - t0:.3f} s"
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
        if (args.real_time or args.action_delay or args.think_ms > 0) and hasattr(remote, "latency_stats"):
            print("latency stats (env.unwrapped.latency_stats):")
            print(remote.latency_stats.format())
    finally:
        env.close()
    return 0
