"""OpenAIRemoteEnv: a Gymnasium env whose world lives in a sim process.

Runs in the agent process. ``reset``/``step``/``render`` become requests to
the sim (see :mod:`remoteenv.protocol`); spaces and metadata come from the
sim's handshake, so they are declared once, in the scene.
"""

from __future__ import annotations

import os
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from remoteenv import protocol
from remoteenv.connection import Connection
from remoteenv.errors import RemoteEnvError
from remoteenv.launcher import Launcher


def check_action(space: gym.Space, action: Any, where: str = "") -> Any:
    """Return ``action`` in the wire form for ``space``, or raise ``ValueError``
    naming the space and the value if it does not belong to the space."""
    if isinstance(space, gym.spaces.Box):
        arr = np.asarray(action)
        if arr.dtype.kind not in "biuf":
            raise ValueError(f"{where}action {action!r:.200} of dtype {arr.dtype} does not fit {space}")
        arr = arr.astype(space.dtype, copy=False)
        if arr.shape != space.shape:
            raise ValueError(f"{where}action of shape {arr.shape} does not fit {space}: {action!r:.200}")
        if np.isnan(arr).any() if arr.dtype.kind == "f" else False:
            raise ValueError(f"{where}action {action!r:.200} contains NaN; space {space}")
        if not space.contains(arr):
            raise ValueError(f"{where}action {action!r:.200} is outside {space}")
        return arr
    if isinstance(space, gym.spaces.Discrete):
        if isinstance(action, np.ndarray) and action.shape == ():
            action = action.item()
        if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
            raise ValueError(f"{where}action {action!r:.200} is not an int of {space}")
        action = int(action)
        if not space.contains(action):
            raise ValueError(f"{where}action {action} is outside {space}")
        return action
    if not space.contains(action):
        raise ValueError(f"{where}action {action!r:.200} is not in {space}")
    return action


class OpenAIRemoteEnv(gym.Env):
    """A Gymnasium env served by a sim process that this env launches.

    Usually created with ``gymnasium.make("remoteenv/CartPole-v0", ...)``;
    keyword arguments that are not listed below are passed on to the scene's
    env class in the sim process (they must be JSON-serializable).

    Args:
        scene: path of the scene script to launch.
        render_mode: ``"rgb_array"`` renders offscreen in the sim process.
        real_time: run the sim on a paced wall clock (see README, real time).
        real_time_factor: simulated seconds per wall-clock second.
        action_delay: lock-step; an action takes effect this many ticks later.
        seed: seed of the sim's RNG until the first ``reset(seed=...)``.
        transport: ``"ipc"`` or ``"tcp"`` (loopback, OS-assigned port).
        timeout: seconds to wait for any one reply before
            :class:`remoteenv.RemoteEnvTimeout` (a dead sim is reported within
            ~0.1 s regardless).
        startup_timeout: seconds to wait for the sim to start.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": None}

    def __init__(
        self,
        scene: str | os.PathLike[str],
        render_mode: str | None = None,
        *,
        real_time: bool = False,
        real_time_factor: float = 1.0,
        action_delay: int = 0,
        seed: int | None = None,
        transport: str = "ipc",
        timeout: float | None = 60.0,
        startup_timeout: float = 60.0,
        **scene_kwargs: Any,
    ) -> None:
        self.render_mode = render_mode
        self.scene = os.fspath(scene)
        self._launcher: Launcher | None = None
        self._conn: Connection | None = None
        self._launcher = Launcher(
            self.scene,
            1,
            seed=seed,
            env_kwargs=scene_kwargs,
            render_mode=render_mode,
            transport=transport,
            startup_timeout=startup_timeout,
            real_time=real_time,
            real_time_factor=real_time_factor,
            action_delay=action_delay,
        )
        sim = self._launcher.sims[0]
        try:
            self._conn = Connection(
                sim.endpoint or "", instance=0, timeout=timeout, death_check=sim.death
            )
            self._handshake(startup_timeout)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ setup

    def _handshake(self, timeout: float) -> None:
        assert self._conn is not None
        hs = self._conn.request("handshake", timeout=timeout, protocol=protocol.PROTOCOL_VERSION)
        self.handshake: dict[str, Any] = hs
        self.observation_space = protocol.space_from_wire(hs["observation_space"])
        self.action_space = protocol.space_from_wire(hs["action_space"])
        meta = hs["metadata"]
        self.metadata = {
            "render_modes": list(meta["render_modes"]),
            "render_fps": meta["render_fps"],
        }
        #: Simulated seconds per step.
        self.dt: float = float(meta["dt"])

    @property
    def pid(self) -> int | None:
        """Process id of the sim process (None once closed)."""
        if self._launcher is None or self._launcher.closed:
            return None
        return self._launcher.pids[0]

    @property
    def launcher(self) -> Launcher | None:
        return self._launcher

    # ------------------------------------------------------------ gym API

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode in the sim. ``seed`` is forwarded and reseeds the sim's RNG."""
        super().reset(seed=seed)
        reply = self._request("reset", seed=seed, options=options)
        return reply["obs"], reply["info"]

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Advance the sim by one control tick (``self.dt`` simulated seconds)."""
        wire_action = check_action(self.action_space, action)
        reply = self._request("step", action=wire_action)
        return reply["obs"], reply["reward"], reply["terminated"], reply["truncated"], reply["info"]

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """With ``render_mode="rgb_array"``: the current frame, uint8 H x W x 3."""
        if self.render_mode != "rgb_array":
            return None
        return self._request("render")["frame"]

    def close(self) -> None:
        """Ask the sim to exit, then make sure it has (no process or socket file remains)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.request("close", timeout=1.0)
            except RemoteEnvError:
                pass
            conn.close()
        launcher, self._launcher = self._launcher, None
        if launcher is not None:
            launcher.close()
        super().close()

    def _request(self, cmd: str, **args: Any) -> dict[str, Any]:
        if self._conn is None:
            raise RemoteEnvError(
                f"{cmd} on a closed OpenAIRemoteEnv ({os.path.basename(self.scene)}); create a new env",
                kind="state",
            )
        return self._conn.request(cmd, **args)
