"""The scene command line and the wait for a sim's ready file.

Runs wherever sims are started for an agent: in the agent process (the local
:class:`remoteenv.Launcher`) or in a Ray actor on a cluster node
(:mod:`remoteenv.integrations.ray`). Both build the same command line here, so a sim
started either way gets the same arguments (see
:func:`remoteenv.sim.scene_main.scene_argument_parser` for their meaning).
The run options travel whole (:class:`~remoteenv.wire.run_options.options.RunOptions`):
the real-time ones as flags; the delay specs are not arguments: the launcher
writes them to a delay file in its private dir
(:mod:`remoteenv.wire.delays.delay_file`) and passes its path.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

from remoteenv.agent.errors import LimitError, RemoteEnvError, SceneArgumentError
from remoteenv.wire.delays.delay_file import write_delay_file
from remoteenv.wire.files.file_reads import UnreadableFile, read_json
from remoteenv.wire.run_options.options import RunOptions
from remoteenv.wire.wire_errors import RESOURCES_MARKER, SCENE_ARGS_MARKER

#: Largest ready file read (a sim writes its endpoint and pid: well under 1 KiB).
READY_FILE_LIMIT = 64 << 10
T = TypeVar("T")
#: Longest pause (seconds) between two looks for a starting sim's file: what
#: a sim that is ready waits, at most, to be noticed (a look, a failed open
#: and a poll of the process, costs the agent microseconds).
LONGEST_LOOK_S = 0.002


def scene_command(
    scene: str,
    address: str,
    *,
    instance: int,
    worlds: int,
    env_kwargs: dict[str, Any],
    parent_pid: int,
    ready_file: str,
    private_dir: str,
    seed: int | None = None,
    render_mode: str | None = None,
    run: RunOptions = RunOptions(),
    delay_file: str | None = None,
    curve_files: tuple[str, str] | None = None,
    allow_remote: bool = False,
    extra_args: Sequence[str] = (),
    python: str = sys.executable,
) -> list[str]:
    """The argv that starts scene script ``scene`` as sim ``instance``, bound to ``address``.

    ``curve_files`` is ``(server secret key file, allowed client keys file)``
    to turn CURVE on; ``allow_remote`` permits an address beyond loopback
    (which needs CURVE). ``run``: the sim's run options, as flags
    (:meth:`~remoteenv.wire.run_options.options.RunOptions.scene_arguments`)
    and, for their delays, the delay file at ``delay_file`` (see
    :func:`write_sim_delay_file`; None without delays). ``python`` is the
    interpreter that runs the scene."""
    cmd = [
        python,
        scene,
        "--address",
        address,
        "--instance",
        str(instance),
        "--worlds",
        str(worlds),
        "--env-kwargs",
        json.dumps(env_kwargs),
        "--parent-pid",
        str(parent_pid),
        "--ready-file",
        ready_file,
        "--private-dir",
        private_dir,
    ]
    if curve_files is not None:
        cmd += ["--curve-secret-key-file", curve_files[0], "--curve-client-keys-file", curve_files[1]]
        if allow_remote:
            cmd += ["--allow-remote"]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    if render_mode is not None:
        cmd += ["--render-mode", render_mode]
    cmd += run.scene_arguments()
    if delay_file is not None:
        cmd += ["--delay-file", delay_file]
    return cmd + list(extra_args)


def launch_environment(render_mode: str | None) -> dict[str, str]:
    """The environment of a sim process started here: ours, with
    ``MUJOCO_GL=egl`` unless it says otherwise or the sim opens a window
    (``render_mode="human"``), and ``LP_NUM_THREADS=1`` unless it says
    otherwise: Mesa's software renderer (llvmpipe) starts that many rasteriser
    threads per process (default: one per CPU), and a camera image of up to
    64x64 pixels is one of its tiles, which one thread rasterises anyway. Four
    rendering processes on the 2-CPU machine, 64x64 frames: the same frames/s
    within noise, 2-4% less CPU per frame and 2.5x fewer context switches
    per frame with one thread (docs/cameras.md)."""
    env = dict(os.environ)
    if render_mode != "human":
        env.setdefault("MUJOCO_GL", "egl")
    env.setdefault("LP_NUM_THREADS", "1")
    return env


def write_sim_delay_file(private_dir: str, instance: int, text: str | None) -> str | None:
    """Write sim ``instance``'s delay file (``text`` from
    :func:`remoteenv.wire.delays.delay_file.delay_file_text`) into ``private_dir`` as
    ``sim-<instance>.delays.json``, mode 0600, replacing one a previous launch
    of the instance left; return its path (None, and no file, when ``text`` is None)."""
    if text is None:
        return None
    path = os.path.join(private_dir, f"sim-{instance}.delays.json")
    if os.path.lexists(path):
        os.unlink(path)
    write_delay_file(path, text)
    return path


class StartingSim(Protocol):
    """What :func:`wait_ready` needs of a sim that is starting."""

    instance: int
    ready_file: str
    endpoint: str | None

    @property
    def pid(self) -> int: ...

    def death(self) -> str | None: ...

    def stderr_tail(self, lines: int = ...) -> str: ...


def scene_exception(stderr: str) -> tuple[str, str] | None:
    """The exception line (``ValueError: ...``) of the last Python traceback in
    ``stderr`` and that traceback, or None if it holds none."""
    lines = stderr.splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("Traceback (most recent call last):")]
    if not starts:
        return None
    for line in lines[starts[-1] + 1 :]:
        if line and not line[0].isspace():
            return line[:500], "\n".join(lines[starts[-1] :])
    return None


def startup_failure(sim: StartingSim, what: str, why: str) -> RemoteEnvError:
    """The error for a sim that exited before reporting ready; ``why`` is its
    ``death()`` text, ``what`` names the scene. A
    :class:`~remoteenv.agent.errors.SceneArgumentError` (a ``TypeError``) when
    the scene refused its keyword arguments (the sim says so on stderr), a
    :class:`~remoteenv.agent.errors.LimitError` when its worlds would not fit in
    memory (the same way), else
    a launch error, with a hint when the script exited cleanly without
    serving (it never called ``run_scene``)."""
    tail = sim.stderr_tail().splitlines()
    refused = [line for line in tail if SCENE_ARGS_MARKER in line]
    if refused:
        reason = refused[-1].split(SCENE_ARGS_MARKER, 1)[1].strip()
        return SceneArgumentError(f"{reason} (sim instance {sim.instance} of {what})", instance=sim.instance)
    too_many = [line for line in tail if RESOURCES_MARKER in line]
    if too_many:
        return LimitError(too_many[-1].split(RESOURCES_MARKER, 1)[1].strip()[:1000], instance=sim.instance)
    raised = scene_exception(sim.stderr_tail(lines=400))
    if raised is not None:  # the scene's own exception first, then how the process ended and its traceback
        ended = why.split("; last lines of its stderr:", 1)[0]
        text = (
            f"sim instance {sim.instance} of {what} failed to start: {raised[0]}\n{ended}; its traceback:\n{raised[1]}"
        )
    else:
        text = f"sim instance {sim.instance} of {what} failed to start: {why}"
    if "exited with code 0" in why:
        text += (
            "\nIt exited without serving: did the script call run_scene(YourEnv) under "
            '`if __name__ == "__main__":`? (see remoteenv.sim.run_scene)'
        )
    return RemoteEnvError(text, kind="launch", instance=sim.instance)


def wait_ready(sim: StartingSim, timeout: float, what: str) -> None:
    """Wait until ``sim`` has written its ready file and set ``sim.endpoint``.

    Polls the file (see :func:`wait_for`), never a fixed sleep. Raises
    :class:`RemoteEnvError` (kind ``"launch"``) if the process exits first or
    ``timeout`` seconds pass; ``what`` names the sim in the message (e.g. the
    scene's file name)."""

    def look() -> bool | None:
        try:
            info = read_json(sim.ready_file, READY_FILE_LIMIT, what="ready file")
            sim.endpoint = str(info["endpoint"]).replace("tcp://0.0.0.0:", "tcp://127.0.0.1:")
            return True
        except (FileNotFoundError, UnreadableFile, KeyError, TypeError):
            return None  # not there yet, or half written: look again

    wait_for(sim, look, timeout, what, "report ready")


def wait_for(sim: StartingSim, look: Callable[[], T | None], timeout: float, what: str, doing: str) -> T:
    """What ``look()`` finds once it finds something (not None), looking every
    1 ms, growing to :data:`LONGEST_LOOK_S` (a forked sim starts within tens
    of milliseconds, and each look costs microseconds). Raises :class:`RemoteEnvError` (kind
    ``"launch"``) if the process exits first or ``timeout`` seconds pass,
    naming ``what`` (the scene's file name) and what the sim did not do in
    time (``doing``, e.g. "report ready")."""
    deadline = time.monotonic() + timeout
    delay = 0.001
    while True:
        found = look()
        if found is not None:
            return found
        why = sim.death()
        if why is not None:
            raise startup_failure(sim, what, why)
        if time.monotonic() > deadline:
            raise RemoteEnvError(
                f"sim instance {sim.instance} (pid {sim.pid}) of {what} did not {doing} within "
                f"{timeout:g} s; raise startup_timeout= if the machine is busy. Its stderr so far:\n"
                f"{sim.stderr_tail()}",
                kind="launch",
                instance=sim.instance,
            )
        time.sleep(delay)
        delay = min(delay * 1.2, LONGEST_LOOK_S)
