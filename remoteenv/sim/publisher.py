"""Frame publisher: a sim process that streams rendered frames and labels.

Runs in the sim process; the agent-side reader is
:class:`remoteenv.integrations.frame_dataset.RemoteIterableDataset`. This is blendtorch's other
half: instead of answering step requests, the sim drives its own world with
random actions and sends what it renders, as its reader asks for it.

Started as ``python publisher.py --scene <scene script> --address ...``: the
scene command line of :mod:`remoteenv.sim.scene_main` plus the flags below,
so :class:`remoteenv.Launcher` starts publishers exactly like sims
(``Launcher(publisher.__file__, extra_args=["--scene", ...])``).

Wire
----
The publisher binds one ZeroMQ ROUTER socket (loopback or ipc only); its
reader connects a DEALER. Frames are rendered on demand: the reader grants
*credit* with ``{"credit": n}`` (:mod:`remoteenv.wire.messages.stream_credit`: msgpack,
``1 <= n <= WINDOW``), and the publisher renders and sends one item per
credit, never more than ``WINDOW`` ahead. Each item is one msgpack map, encoded with
:mod:`remoteenv.protocol` (numpy arrays as extension type 1; never pickle)::

    {"instance": int, "index": int, "episode": int, "step": int,
     "frame": uint8 array H x W x 3, "labels": map}

Frames are the scene's ``render()`` (its ``default_camera``, ``width`` x
``height``), rendered cheaply by default: without multisampling and shadows,
as camera observations are (docs/cameras.md; at 64x64 under software
OpenGL about 0.7 ms a frame against 36 ms at MuJoCo's default quality).
``--quality`` renders them at the MJCF's own quality.

``index`` counts this publisher's items from 0 without gaps, so a reader can
prove it lost nothing. ``step`` is the control tick within ``episode`` (0 is
the state right after reset). ``labels`` come from the scene: if its env class
defines ``stream_labels(self, obs, info) -> dict``, that; otherwise
``{"obs", "qpos", "qvel", "sim_time"}``.

The stream is endless and goes on across readers: a reader that connects
later (the next pass over a dataset) gets the next item, so a reader that
asks for exactly what it reads leaves nothing behind and the next one starts
at the following index. The newest reader to grant credit is the one served
(the credit of an earlier one is void, and it is told so with
``{"superseded": true}``), so exactly one reader should read a publisher at
a time. Credit messages that are not a map with one int
``credit`` in range are dropped. An item the publisher could not deliver
(its reader disconnected) goes to the next reader. The publisher runs until
SIGTERM/SIGINT or the launching process exits.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from collections.abc import Iterator, Sequence
from typing import Any

if __name__ == "__main__" and sys.path and os.path.abspath(sys.path[0]) == os.path.dirname(os.path.abspath(__file__)):
    # Run as a script: keep this folder's module names (server, viewer, ...) off the import path.
    sys.path.pop(0)

import zmq

from remoteenv.sim.process.lifecycle import exit_on_sigterm, remove_ipc_file, write_ready_file
from remoteenv.sim.process.log import log_to_stderr
from remoteenv.sim.process.orphan import CHECK_INTERVAL_S, parent_alive
from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene_main import scene_argument_parser
from remoteenv.wire import protocol
from remoteenv.wire.addresses import is_loopback
from remoteenv.wire.messages.stream_credit import MAX_CREDIT_BYTES, WINDOW, parse_credit, superseded_message

_POLL_MS = round(CHECK_INTERVAL_S * 1000)


def load_env_class(scene_script: str, class_name: str | None = None) -> type[BaseEnv]:
    """Import a scene script (without running its ``main``) and return its env class:
    ``class_name`` if given, else the one :class:`BaseEnv` subclass it defines."""
    path = os.path.abspath(scene_script)
    name = "_remoteenv_scene_" + os.path.splitext(os.path.basename(path))[0]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ValueError(f"cannot import scene script {path!r}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    if class_name is not None:
        cls = getattr(module, class_name, None)
        if not (isinstance(cls, type) and issubclass(cls, BaseEnv)):
            raise ValueError(f"{path} has no BaseEnv subclass named {class_name!r}")
        return cls
    found = [
        obj
        for obj in vars(module).values()
        if isinstance(obj, type) and issubclass(obj, BaseEnv) and obj.__module__ == name
    ]
    if len(found) != 1:
        raise ValueError(
            f"{path} defines {len(found)} BaseEnv subclasses "
            f"({', '.join(c.__name__ for c in found) or 'none'}); name one with --env-class"
        )
    return found[0]


def default_labels(env: BaseEnv, obs: Any, info: dict[str, Any]) -> dict[str, Any]:
    """Labels of a frame when the scene defines no ``stream_labels``."""
    return {
        "obs": obs,
        "qpos": env.data.qpos.copy(),
        "qvel": env.data.qvel.copy(),
        "sim_time": float(env.data.time),
    }


class FramePublisher:
    """Drives one world with random actions and sends a frame per control tick,
    one per credit its reader grants (see the module docstring).

    Args:
        env: the world; must support ``render_mode="rgb_array"``.
        address: ZeroMQ endpoint to bind (ipc or loopback tcp; ``:*`` port allowed).
        instance: this publisher's index, sent with every item.
        seed: seeds the world's resets and the random actions.
        episode_steps: control ticks per episode before a reset (episodes also
            end when the scene terminates them).
        parent_pid: stop when this process is no longer our parent.
        quality: render at the MJCF's quality; False (the default): without
            multisampling and shadows (``env.render_quality``).
    """

    def __init__(
        self,
        env: BaseEnv,
        address: str,
        *,
        instance: int = 0,
        seed: int | None = None,
        episode_steps: int = 100,
        parent_pid: int | None = None,
        quality: bool = False,
    ) -> None:
        if env.render_mode != "rgb_array":
            raise ValueError("a frame publisher renders offscreen: create the env with render_mode='rgb_array'")
        if not is_loopback(address):
            raise ValueError(f"refusing to bind {address!r}: frame publishers bind ipc:// or loopback only")
        if episode_steps < 1:
            raise ValueError(f"episode_steps must be >= 1, got {episode_steps}")
        self.env = env
        env.render_quality = bool(quality)
        self.instance = instance
        self.seed = seed
        self.episode_steps = episode_steps
        self.parent_pid = parent_pid
        self._ctx: zmq.Context[Any] = zmq.Context.instance()
        self.socket = self._ctx.socket(zmq.ROUTER)
        self.socket.setsockopt(zmq.ROUTER_MANDATORY, 1)  # an undeliverable item raises, and is kept
        self.socket.setsockopt(zmq.SNDHWM, WINDOW)
        self.socket.setsockopt(zmq.RCVHWM, 4 * WINDOW)
        self.socket.setsockopt(zmq.MAXMSGSIZE, MAX_CREDIT_BYTES)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.bind(address)
        self.endpoint: str = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        self._labels = getattr(env, "stream_labels", None)
        #: Items sent so far (the next item's ``index``).
        self.sent = 0
        self._reader: bytes | None = None
        self._credit = 0

    def _parent_gone(self) -> bool:
        return self.parent_pid is not None and not parent_alive(self.parent_pid)

    def _take_credit(self, wait_ms: int) -> None:
        """Read the credit messages that arrived (waiting up to ``wait_ms`` for the first)."""
        while self.socket.poll(wait_ms, zmq.POLLIN):
            wait_ms = 0
            frames = self.socket.recv_multipart(zmq.NOBLOCK)
            credit = parse_credit(frames[1]) if len(frames) == 2 else None
            if credit is None:
                continue
            if frames[0] != self._reader:  # a new reader takes over; the old one's credit is void
                if self._reader is not None:
                    try:
                        self.socket.send_multipart([self._reader, superseded_message()], zmq.NOBLOCK)
                    except zmq.ZMQError:
                        pass  # it is gone (or its queue is full: it will time out instead)
                self._reader, self._credit = frames[0], 0
            self._credit = min(self._credit + credit, WINDOW)

    def _items(self) -> Iterator[bytes]:
        """The endless stream of encoded items, rendered as they are asked for."""
        env = self.env
        env.action_space.seed(self.seed)
        obs, info = env.reset(seed=self.seed)
        episode, step = 0, 0
        while True:
            labels = self._labels(obs, info) if self._labels else default_labels(env, obs, info)
            yield protocol.pack(
                {
                    "instance": self.instance,
                    "index": self.sent,
                    "episode": episode,
                    "step": step,
                    "frame": env.render(),
                    "labels": labels,
                }
            )
            obs, _, terminated, info = env.step(env.action_space.sample())
            step += 1
            if terminated or step >= self.episode_steps:
                obs, info = env.reset()
                episode, step = episode + 1, 0

    def run(self) -> None:
        """Serve items against credit until the parent process is gone."""
        items = self._items()
        pending: bytes | None = None
        while not self._parent_gone():
            self._take_credit(0 if self._credit else _POLL_MS)
            if not self._credit or self._reader is None:
                continue
            if pending is None:
                pending = next(items)
            try:
                self.socket.send_multipart([self._reader, pending], zmq.NOBLOCK, copy=False)
            except zmq.ZMQError as exc:
                if exc.errno == zmq.EHOSTUNREACH:  # the reader left: keep the item for the next one
                    self._reader, self._credit = None, 0
                    continue
                if exc.errno == zmq.EAGAIN:  # its queue is full (more credit than room): wait for room
                    self._take_credit(_POLL_MS // 10)
                    continue
                raise
            pending = None
            self.sent += 1
            self._credit -= 1

    def close(self) -> None:
        self.socket.close(linger=0)
        self.env.close()


def main(argv: Sequence[str] | None = None) -> None:
    parser = scene_argument_parser(__doc__.splitlines()[0])
    parser.add_argument("--scene", required=True, help="path of the scene script whose world to publish")
    parser.add_argument("--env-class", default=None, help="env class in the scene script (if it has several)")
    parser.add_argument("--episode-steps", type=int, default=100, help="control ticks per episode")
    parser.add_argument(
        "--quality", action="store_true", help="render at the MJCF's quality (default: no multisampling, no shadows)"
    )
    args = parser.parse_args(argv)
    log_to_stderr(args.instance)
    if args.real_time or args.action_delay or args.delay_file or args.worlds != 1:
        parser.error(
            "a publisher drives one world lock-step: --real-time, --action-delay, --delay-file, --worlds do not apply"
        )
    env_kwargs: dict[str, Any] = json.loads(args.env_kwargs)
    env_kwargs["render_mode"] = "rgb_array"
    env = load_env_class(args.scene, args.env_class)(**env_kwargs)
    exit_on_sigterm()
    publisher = FramePublisher(
        env,
        args.address,
        instance=args.instance,
        seed=args.seed,
        episode_steps=args.episode_steps,
        parent_pid=args.parent_pid,
        quality=args.quality,
    )
    try:
        if args.ready_file:
            write_ready_file(args.ready_file, publisher.endpoint, args.instance)
        publisher.run()
    finally:
        publisher.close()
        remove_ipc_file(publisher.endpoint)


if __name__ == "__main__":
    main()
