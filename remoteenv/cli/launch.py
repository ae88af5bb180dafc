"""``python -m remoteenv launch <scene>``: start sims for other processes to attach to.

The command starts the sims, writes a launch-info file (see
:mod:`remoteenv.agent.launch.attach`) and stays in the foreground. The sims live exactly as
long as the command: on Ctrl-C or SIGTERM it stops them and removes the
launch-info file (and the client key file); if the command is killed outright,
the sims notice their parent is gone and exit by themselves. If a sim dies,
the command stops the others and exits with status 1.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sys
import time
from typing import Any

from remoteenv.cli.arguments import (
    check_can_write,
    json_map,
    non_negative_int,
    positive_factor,
    positive_int,
)
from remoteenv.wire.run_options.real_time_modes import ELASTIC, REAL_TIME_MODES

_WATCH_S = 0.2


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "launch",
        help="start sims and write a launch-info file for OpenAIRemoteEnv.attach",
        description="Start sim processes of a scene, write a launch-info file other processes "
        "attach to (OpenAIRemoteEnv.attach, RemoteVectorEnv.attach, gymnasium.make(id, "
        "attach=FILE)), and keep them running until Ctrl-C / SIGTERM.",
    )
    p.add_argument("scene", help="shipped scene name (cartpole, reacher) or path of a scene script")
    p.add_argument("--instances", type=positive_int, default=1, help="sim processes to start (default 1)")
    p.add_argument("--worlds", type=positive_int, default=1, help="MuJoCo worlds per sim process (default 1)")
    p.add_argument("--out", default="launch.json", help="launch-info file to write (default launch.json)")
    p.add_argument("--seed", type=non_negative_int, default=None, help="RNG seed; instance i uses seed + i * worlds")
    p.add_argument("--env-kwargs", default="{}", help="JSON map of keyword arguments for the scene's env")
    p.add_argument("--render-mode", default=None, choices=["rgb_array", "human"], help="render mode of the sims")
    p.add_argument(
        "--transport",
        choices=["ipc", "tcp"],
        default="ipc",
        help="ipc socket in a private dir (default) or tcp on 127.0.0.1",
    )
    p.add_argument("--bind-host", default=None, help="bind tcp on this interface; beyond loopback this turns CURVE on")
    p.add_argument(
        "--public-host",
        default=None,
        help="host name other machines reach the sims by, written into the file "
        "(default: --bind-host, or this machine's name for 0.0.0.0)",
    )
    p.add_argument("--curve", action="store_true", help="encrypt with ZMQ CURVE even on loopback")
    p.add_argument("--real-time", action="store_true", help="run the sims on a paced wall clock")
    p.add_argument("--real-time-mode", choices=REAL_TIME_MODES, default=ELASTIC, help="with --real-time: the regime")
    p.add_argument(
        "--real-time-factor",
        type=positive_factor,
        default=1.0,
        help="simulated seconds per wall-clock second in real-time mode",
    )
    p.add_argument(
        "--action-delay",
        type=non_negative_int,
        default=0,
        help="lock-step: an action takes effect this many ticks later",
    )
    p.set_defaults(run=run)


def _scene_script(scene: str) -> str:
    from remoteenv import scene_path

    if os.path.isfile(scene):
        return os.path.abspath(scene)
    return scene_path(scene)


def _advertised(endpoint: str, args: argparse.Namespace) -> str:
    """The endpoint as another machine should dial it."""
    if not args.bind_host or not endpoint.startswith("tcp://"):
        return endpoint
    host = args.public_host or (socket.gethostname() if args.bind_host in ("0.0.0.0", "*") else args.bind_host)
    port = endpoint.rsplit(":", 1)[1]
    return f"tcp://{host}:{port}"


def run(args: argparse.Namespace) -> int:
    from remoteenv.agent.errors import RemoteEnvError
    from remoteenv.agent.launch.attach import AttachedSim, LaunchInfo, write_launch_info
    from remoteenv.agent.launch.launcher import Launcher
    from remoteenv.wire.files.keys import write_secret_key
    from remoteenv.wire.messages.handshake import handshake_request, parse_handshake

    env_kwargs = json_map(args.env_kwargs, "--env-kwargs")
    out = os.path.abspath(args.out)
    check_can_write(out, "--out")  # before any sim starts

    def _stop(signum: int, _frame: Any) -> None:
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, _stop)
    written: list[str] = []
    try:
        launcher = Launcher(
            _scene_script(args.scene),
            args.instances,
            seed=args.seed,
            worlds_per_instance=args.worlds,
            env_kwargs=env_kwargs,
            render_mode=args.render_mode,
            transport=args.transport,
            real_time=args.real_time,
            real_time_factor=args.real_time_factor,
            real_time_mode=args.real_time_mode,
            action_delay=args.action_delay,
            bind_host=args.bind_host,
            curve=True if args.curve else None,
        )
    except (RemoteEnvError, FileNotFoundError, ValueError) as exc:
        print(f"launch failed: {exc}", file=sys.stderr)
        return 1
    try:
        keys = launcher.curve_client_keypair
        conn = launcher.connect(0, timeout=60.0)
        try:
            env_id = parse_handshake(conn.request("handshake", **handshake_request())).env_id
        finally:
            conn.close()
        key_file = None
        if keys is not None:
            # In the private dir (0700): it goes with the sims, however this command ends.
            key_file = os.path.join(launcher.workdir, f"launch.{os.path.basename(os.path.splitext(out)[0])}.key_secret")
            write_secret_key(key_file, keys.secret)
        info = LaunchInfo(
            scene=launcher.scene,
            env_id=env_id,
            host=socket.gethostname(),
            launcher_pid=os.getpid(),
            worlds_per_instance=args.worlds,
            render_mode=args.render_mode,
            real_time=args.real_time,
            real_time_factor=args.real_time_factor,
            action_delay=args.action_delay,
            curve_client_secret_key_file=key_file,
            instances=[
                AttachedSim(
                    instance=s.instance,
                    endpoint=_advertised(s.endpoint or "", args),
                    pid=s.pid,
                    curve_server_key=s.curve_server_key,
                )
                for s in launcher.sims
            ],
        )
        try:
            write_launch_info(out, info)
        except OSError as exc:
            print(f"launch failed: cannot write {out!r}: {exc}; stopping the sims", file=sys.stderr)
            return 1
        written.append(out)
        for s in info.instances:
            print(f"instance {s.instance}: pid {s.pid} at {s.endpoint}")
        if key_file is not None:
            print(f"CURVE client secret key (mode 0600, removed with the sims): {key_file}")
        print(
            f"{env_id}: {args.instances} sim(s) running; wrote {out}. "
            "Attach with OpenAIRemoteEnv.attach(FILE); Ctrl-C or SIGTERM stops them.",
            flush=True,
        )
        while True:
            for sim in launcher.sims:
                why = sim.death()
                if why is not None:
                    print(f"sim instance {sim.instance} stopped: {why}; stopping the others", file=sys.stderr)
                    return 1
            time.sleep(_WATCH_S)
    except KeyboardInterrupt:
        return 0
    except SystemExit as exc:
        return 0 if exc.code == 128 + signal.SIGTERM else int(exc.code or 0)
    finally:
        for path in written:
            try:
                os.unlink(path)
            except OSError:
                pass
        launcher.close()
        print("sims stopped", flush=True)
