"""The command line every scene script shares: ``python <scene script> --address ...``. Runs in the sim process."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from typing import Any

from remoteenv.sim.process.layout_gate import GoSignal, report_and_wait
from remoteenv.sim.process.log import log_to_stderr
from remoteenv.sim.process.pacing_levers import GC_MODES, apply_levers
from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.world_builds import WorldsDoNotFit, build_worlds
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.wire.delays.channel_rules import DELIVERY_RULES, NEWEST, ChannelRules
from remoteenv.wire.delays.delay_file import read_delay_file
from remoteenv.wire.delays.delay_specs import SECONDS, TICKS, DelaySpec, as_delay, delay_from_wire
from remoteenv.wire.files.keys import read_key, read_keys
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.run_options.real_time_modes import ELASTIC, REAL_TIME_MODES
from remoteenv.wire.wire_errors import (
    EXIT_RESOURCES,
    EXIT_SCENE_ARGS,
    RESOURCES_MARKER,
    SCENE_ARGS_MARKER,
    ProtocolError,
    short_repr,
)


def _delay_argument(text: str, unit: str) -> DelaySpec:
    """A delay given on the command line: a number, or a spec's wire form as JSON."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        raise argparse.ArgumentTypeError(f"not a number nor JSON: {short_repr(text)}") from None
    try:
        if isinstance(value, dict):
            return as_delay(delay_from_wire(value), unit)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"expected a number or a map, got {short_repr(value)}")
        return as_delay(value, unit)
    except (ProtocolError, ValueError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def tick_delay_argument(text: str) -> DelaySpec:
    """``--action-delay``/``--obs-delay``: ticks, an int or a JSON spec."""
    return _delay_argument(text, TICKS)


def seconds_delay_argument(text: str) -> DelaySpec:
    """``--link-delay``: seconds, a number or a JSON spec."""
    return _delay_argument(text, SECONDS)


def apply_channel_flags(args: argparse.Namespace) -> None:
    """Set ``args.channel`` from ``--action-delivery``, ``--obs-delivery`` and
    ``--delayed-rewards`` (None for the default rules)."""
    rules = ChannelRules(args.action_delivery, args.obs_delivery, args.delayed_rewards)
    args.channel = None if rules.is_default else rules


def apply_delay_file(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Set ``args.action_delay``/``obs_delay``/``link_delay`` from ``--delay-file``;
    exits through ``parser.error`` if the file is bad or repeats a delay flag."""
    try:
        specs = read_delay_file(args.delay_file)
    except ProtocolError as exc:
        parser.error(str(exc))
    defaults = {"action_delay": 0, "obs_delay": 0, "link_delay": None, "channel": None}
    for key, spec in specs.items():
        if getattr(args, key, None) != defaults[key]:
            flag = (
                "--action-delivery/--obs-delivery/--delayed-rewards"
                if key == "channel"
                else "--" + key.replace("_", "-")
            )
            parser.error(f"{flag} is given twice: as a flag and in --delay-file")
        setattr(args, key, spec)


def run_options_from_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> RunOptions:
    """The run options of a parsed scene command line: the real-time flags, the
    delay flags or ``--delay-file`` (exits through ``parser.error`` if the file
    is bad or repeats a delay flag) and the channel rules' flags. A ValueError
    (as :class:`~remoteenv.wire.run_options.options.RunOptions` raises it) for
    options that contradict each other."""
    apply_channel_flags(args)
    if args.delay_file is not None:
        apply_delay_file(parser, args)
    channel = args.channel.to_wire() if args.channel is not None else {}
    return RunOptions(
        real_time=args.real_time,
        real_time_factor=args.real_time_factor,
        real_time_mode=args.real_time_mode,
        action_delay=args.action_delay,
        obs_delay=args.obs_delay,
        link_delay=args.link_delay,
        physics_threads=args.physics_threads,
        **channel,
    )


def scene_argument_parser(description: str | None = None) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument(
        "--address", required=True, help="ZeroMQ endpoint to bind, e.g. ipc:///tmp/d/sim-0.sock or tcp://127.0.0.1:*"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of the worlds' RNGs until the first reset(seed=...); world w uses seed + w",
    )
    p.add_argument("--instance", type=int, default=0, help="index of this sim process")
    p.add_argument("--worlds", type=int, default=1, help="number of MuJoCo worlds this process hosts")
    p.add_argument(
        "--physics-threads",
        type=int,
        default=None,
        help="lock-step: threads the worlds' physics steps on (default: REMOTEENV_SIM_THREADS, else 1)",
    )
    p.add_argument("--env-kwargs", default="{}", help="JSON map of keyword arguments for the env class")
    p.add_argument("--render-mode", default=None, help="render mode of the env, e.g. rgb_array")
    p.add_argument("--real-time", action="store_true", help="run physics on a paced wall clock")
    p.add_argument(
        "--real-time-factor", type=float, default=1.0, help="simulated seconds per wall-clock second in real-time mode"
    )
    p.add_argument("--real-time-mode", choices=REAL_TIME_MODES, default=ELASTIC, help="the real-time regime")
    p.add_argument(
        "--action-delay",
        type=tick_delay_argument,
        default=0,
        help="lock-step: an action takes effect this many control ticks later: an int, or a delay "
        'spec\'s wire form as JSON, e.g. \'{"kind": "uniform", "unit": "ticks", "low": 0, "high": 3}\'',
    )
    p.add_argument(
        "--obs-delay",
        type=tick_delay_argument,
        default=0,
        help="lock-step: observations arrive this many control ticks late (int or JSON spec, as --action-delay)",
    )
    p.add_argument(
        "--link-delay",
        type=seconds_delay_argument,
        default=None,
        help="real time: emulated extra link delay per action, wall seconds (a number or a JSON spec with unit s)",
    )
    p.add_argument(
        "--delay-file",
        default=None,
        help="a JSON file of delay specs (keys action_delay, obs_delay, link_delay; see "
        "remoteenv.wire.delays.delay_file): how launchers pass them, since a recorded trace is too long for "
        "a command line. A delay given here and as its own flag is refused",
    )
    p.add_argument(
        "--action-delivery",
        choices=DELIVERY_RULES,
        default=NEWEST,
        help="lock-step: which delayed action acts: the newest arrived (default) or in order (TCP-like)",
    )
    p.add_argument("--obs-delivery", choices=DELIVERY_RULES, default=NEWEST, help="the same for observations")
    p.add_argument(
        "--delayed-rewards",
        action="store_true",
        help="lock-step: reward, terminated and the scene's info travel with the delayed observation",
    )
    levers = p.add_argument_group("real-time pacing levers (see remoteenv.sim.process.pacing_levers)")
    levers.add_argument("--rt-priority", type=int, default=0, help="run under SCHED_FIFO at this priority (1..99)")
    levers.add_argument("--rt-cpus", default=None, help="pin the process to these CPUs, e.g. 1 or 0,1")
    levers.add_argument("--rt-gc", choices=GC_MODES, default="auto", help="garbage collector: auto, freeze or off")
    levers.add_argument(
        "--rt-spin-s", type=float, default=None, help="spin this many wall seconds before each deadline"
    )
    p.add_argument("--parent-pid", type=int, default=None, help="exit when this process stops being our parent")
    p.add_argument("--ready-file", default=None, help="write the bound endpoint here as JSON")
    p.add_argument(
        "--allow-remote",
        action="store_true",
        help="permit binding a non-loopback interface (requires --curve-secret-key-file)",
    )
    p.add_argument("--curve-secret-key-file", default=None, help="file holding this server's Z85 CURVE secret key")
    p.add_argument(
        "--curve-client-keys-file",
        default=None,
        help="file of Z85 CURVE public keys (one a line) of the clients allowed to "
        "connect; without it any client knowing the server's public key may",
    )
    p.add_argument(
        "--pipe-fd",
        type=int,
        default=None,
        help="inherited file descriptor of the launcher's socketpair (the local pipe)",
    )
    p.add_argument(
        "--layout-gate",
        default=None,
        help="first measure a scratch world, write what the layout rule reads to this file and wait "
        "for the agent's go (SIGUSR1) before building the worlds (remoteenv.sim.process.layout_gate)",
    )
    p.add_argument(
        "--private-dir",
        default=None,
        help="the launcher's private dir: if the agent dies, remove this instance's "
        "sim-<instance>.* files from it, and the dir once empty",
    )
    return p


def run_scene(
    env_factory: Callable[..., BaseEnv], argv: Sequence[str] | None = None, description: str | None = None
) -> None:
    """Parse the scene command line, build the worlds with ``env_factory(render_mode=..., **env_kwargs)``
    and serve them until told to stop. A scene script's ``main`` is one call of this."""
    parser = scene_argument_parser(description)
    args = parser.parse_args(argv)
    log_to_stderr(args.instance)
    run = run_options_from_arguments(parser, args)
    env_kwargs: dict[str, Any] = json.loads(args.env_kwargs)
    if not isinstance(env_kwargs, dict):
        sys.exit(f"--env-kwargs must be a JSON map, got {args.env_kwargs!r}")
    # A scratch world (measuring what one costs) opens no viewer window.
    scratch_kwargs = dict(env_kwargs)
    if args.render_mode is not None:
        env_kwargs["render_mode"] = args.render_mode
    go = GoSignal() if args.layout_gate else None
    try:
        if go is not None:
            report_and_wait(args.layout_gate, lambda: env_factory(**scratch_kwargs), args.parent_pid, go)
        envs = build_worlds(lambda: env_factory(**env_kwargs), args.worlds, f"sim instance {args.instance}")
    except TypeError as exc:
        if "keyword argument" not in str(exc):
            raise
        # The launcher turns this exit status into a TypeError in the agent.
        print(f"{SCENE_ARGS_MARKER} {exc}", file=sys.stderr)
        sys.exit(EXIT_SCENE_ARGS)
    except WorldsDoNotFit as exc:  # the launcher raises it as a LimitError, one line
        print(f"{RESOURCES_MARKER} {exc}", file=sys.stderr)
        sys.exit(EXIT_RESOURCES)
    if args.seed is not None:
        for w, env in enumerate(envs):
            env.seed_rng(args.seed + w)
    secret = client_keys = None
    if args.curve_secret_key_file:
        secret = read_key(args.curve_secret_key_file)
    if args.curve_client_keys_file:
        client_keys = read_keys(args.curve_client_keys_file)
    server = RemoteControlledAgent(
        envs,
        args.address,
        instance=args.instance,
        parent_pid=args.parent_pid,
        ready_file=args.ready_file,
        run=run,
        seed=args.seed,
        allow_remote=args.allow_remote,
        curve_secret_key=secret,
        curve_client_keys=client_keys,
        private_dir=args.private_dir,
        pipe_fd=args.pipe_fd,
        world_factory=lambda: env_factory(**scratch_kwargs),
    )
    if args.rt_spin_s is not None:
        server.deadline_spin_s = max(0.0, float(args.rt_spin_s))
    cpus = [int(c) for c in args.rt_cpus.split(",")] if args.rt_cpus else None
    on = apply_levers(priority=args.rt_priority, cpus=cpus, gc_mode=args.rt_gc)
    if on:
        logging.getLogger(__name__).info("pacing levers on: %s", ", ".join(on))
    server.serve()
