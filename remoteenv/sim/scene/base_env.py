"""BaseEnv: the env code of a scene, running inside the sim process."""

from __future__ import annotations

import os
from typing import Any, ClassVar, SupportsFloat

import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from remoteenv.sim.scene.camera_rig import CameraRig, cheap_renderer
from remoteenv.sim.scene.cameras import CameraObservation
from remoteenv.sim.scene.model_file import load_model
from remoteenv.sim.scene.obs_check import check_observation
from remoteenv.sim.scene.per_world_hooks import BatchedHooks
from remoteenv.sim.scene.scene_cameras import SceneCameras
from remoteenv.sim.scene.step_check import check_finite_obs, unpack_reset, unpack_step


class BaseEnv(BatchedHooks, SceneCameras):
    """One MuJoCo world and the env logic around it.

    A scene subclasses this and implements :meth:`reset_model`,
    :meth:`prepare_step` and :meth:`post_step`. The base class owns the
    ``MjModel``/``MjData``, ``frame_skip``, the RNG and the declared spaces
    (the optional batched hooks of several worlds at once come from
    :class:`~remoteenv.sim.scene.per_world_hooks.BatchedHooks`), and drives a step as::

        prepare_step(action)                 # e.g. write data.ctrl
        mj_step(model, data) x frame_skip    # the physics substeps
        post_step(action) -> obs, reward, terminated, info

    One call of :meth:`step` is one *control tick*: ``dt = frame_skip *
    model.opt.timestep`` seconds of simulated time. The sim runtime may also
    drive the pieces itself (real-time mode applies an action at the substep
    where it arrives), so subclasses must keep all per-step logic in these hooks.

    Cameras (``cameras=``, a :class:`~remoteenv.sim.scene.cameras.CameraObservation`):
    the hooks keep returning the state obs; :meth:`observe` adds the images, and
    :meth:`camera_geometry` gives the cameras' intrinsics and extrinsics
    (:class:`~remoteenv.sim.scene.scene_cameras.SceneCameras`, docs/cameras.md).

    Truncation (episode time limits) is the agent side's business
    (``gymnasium.make``'s ``max_episode_steps``); ``post_step`` reports only
    termination.

    Class attributes a scene sets:
        env_id: a name for the scene, reported in the handshake.
        metadata: ``render_modes`` supported; ``render_fps`` is derived from dt.
        default_camera: camera name used for rendering, or None for the free camera.
        check_obs_bounds: also check that observations lie inside the
            observation space's bounds (dtype and shape are always checked,
            see :mod:`remoteenv.sim.scene.obs_check`).
        check_finite: also check that observations and rewards hold no NaN
            or infinity (the kind and count of what the hooks return are
            always checked, see :mod:`remoteenv.sim.scene.step_check`).
        stacked_hooks: the scene's batched hooks (:meth:`prepare_steps`,
            :meth:`post_steps`) read and write the worlds' state only through
            :func:`remoteenv.sim.stepping.batch_worlds.stacked` (never through a world's
            ``data``, nor views of it kept from earlier): the worlds of a process
            may then step in one ``mujoco.batch.Batch`` (see :attr:`data`).
            Set it in the scene class's body (``stacked_hooks = True``): the
            agent reads that from the script's source, without running it,
            and starts a first vector env of the scene through the layout
            gate (its first sim measures a scratch world before it builds
            the rest: :mod:`remoteenv.sim.process.layout_gate`) rather than
            a layout it may have to relaunch.
    """

    env_id: ClassVar[str] = "scene"
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"]}
    default_camera: ClassVar[str | None] = None
    check_obs_bounds: ClassVar[bool] = False
    check_finite: ClassVar[bool] = False
    stacked_hooks: ClassVar[bool] = False

    #: While the world steps in a batch (:mod:`remoteenv.sim.stepping.batch_worlds`): the
    #: batch and this world's index in it, through which :attr:`data` is kept current.
    _batch_link: Any = None
    _batch_index: int = 0

    observation_space: spaces.Space
    action_space: spaces.Space

    def __init__(
        self,
        model_path: str | os.PathLike[str],
        frame_skip: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        cameras: CameraObservation | None = None,
    ) -> None:
        if frame_skip < 1:
            raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"{type(self).__name__} does not support render_mode={render_mode!r}; "
                f"supported: {self.metadata['render_modes']}"
            )
        self.model = load_model(os.fspath(model_path), type(self).__name__)
        self._data = mujoco.MjData(self.model)
        self.frame_skip = int(frame_skip)
        #: What the hooks return (the state); the observation adds the cameras' images to it.
        self.state_space = observation_space
        self.observation_space = (
            observation_space if cameras is None else cameras.space(observation_space, self.model.ngeom)
        )
        self.action_space = action_space
        #: The renderers of the declared cameras (None: no camera in the observation).
        self.camera_rig = None if cameras is None else CameraRig(self.model, cameras, type(self).__name__)
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)
        #: ``render()`` at the MJCF's quality (True, the default: videos) or cheaply, without
        #: multisampling and shadows (False: what a frame publisher streams unless asked);
        #: read when the renderer is made, at the first ``render()``.
        self.render_quality = True
        self._renderer: mujoco.Renderer | None = None
        self._viewer: Any = None
        if render_mode == "human":
            from remoteenv.sim.scene.viewer import HumanViewer

            self._viewer = HumanViewer(self.model, self.data)
        self._np_random: np.random.Generator | None = None
        self._np_random_seed: int | None = None

    # ------------------------------------------------------------ properties

    @property
    def data(self) -> mujoco.MjData:
        """This world's ``MjData``. While the world steps in a batch with others
        (a scene with :attr:`stacked_hooks`), the batch holds its state between
        batched steps; reading ``data`` first brings it up to date, exactly as
        ``mj_step`` would have left it, and the batch takes the state back from
        here before the world's next batched step (so changes made through
        ``data`` count). Views of ``data`` kept from earlier are not updated."""
        link = self._batch_link
        if link is not None:
            link.pull(self._batch_index)
        return self._data

    @data.setter
    def data(self, value: mujoco.MjData) -> None:
        if self._batch_link is not None:
            self._batch_link.claim(self._batch_index)
        self._data = value

    @property
    def dt(self) -> float:
        """Simulated seconds per control tick (``frame_skip * timestep``)."""
        return self.model.opt.timestep * self.frame_skip

    @property
    def np_random(self) -> np.random.Generator:
        """The env's RNG, seeded by ``reset(seed=...)`` (random if never seeded)."""
        if self._np_random is None:
            self._np_random, self._np_random_seed = seeding.np_random()
        return self._np_random

    @property
    def np_random_seed(self) -> int:
        """The seed of :attr:`np_random`, as Gymnasium's ``Env.np_random_seed``: the
        last seed a reset or the launch gave, a random one drawn now if never seeded."""
        if self._np_random is None:
            self._np_random, self._np_random_seed = seeding.np_random()
        return int(self._np_random_seed if self._np_random_seed is not None else -1)

    def seed_rng(self, seed: int | None) -> None:
        """Reseed the RNG (as ``reset(seed=...)`` does) without resetting the world."""
        self._np_random, self._np_random_seed = seeding.np_random(seed)

    def default_action(self) -> Any:
        """Action held before the agent's first one after a reset (real-time and
        ``action_delay`` modes). ``None`` (the default) means "no action": the
        scene's :meth:`prepare_step` and :meth:`post_step` must then apply and
        score zero control."""
        return None

    # ------------------------------------------------------------ hooks

    def reset_model(self, options: dict[str, Any] | None) -> tuple[Any, dict[str, Any]]:
        """Put ``self.data`` into a start state drawn from ``self.np_random``.

        Called after ``mj_resetData``. Returns ``(obs, info)``.
        """
        raise NotImplementedError

    def prepare_step(self, action: Any) -> None:
        """Apply ``action`` (validated against ``action_space``, or ``None`` for
        zero control, see :meth:`default_action`), e.g. to ``data.ctrl``."""
        raise NotImplementedError

    def post_step(self, action: Any) -> tuple[Any, SupportsFloat, bool, dict[str, Any]]:
        """After the substeps of one tick: ``(obs, reward, terminated, info)``."""
        raise NotImplementedError

    # ------------------------------------------------------------ driving

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Start an episode. ``seed`` reseeds the RNG; None continues the current stream."""
        if seed is not None:
            self.seed_rng(seed)
        if self._batch_link is not None:  # mj_resetData rewrites all of it: no need to bring it up to date
            self._batch_link.claim(self._batch_index)
        mujoco.mj_resetData(self.model, self._data)
        obs, info = unpack_reset(self.reset_model(options), scene=type(self).__name__)
        self._check_obs(obs, "reset_model")
        return self.observe(obs, fresh=True), info

    def finish_tick(self, action: Any, *, observe: bool = True) -> tuple[Any, SupportsFloat, bool, dict[str, Any]]:
        """:meth:`post_step`, its result checked: four values, a scalar reward,
        a bool ``terminated``, a dict info (:mod:`remoteenv.sim.scene.step_check`)
        and the observation against ``observation_space``. ``observe=False``:
        the hooks' state obs, the cameras not rendered (a tick whose observation
        nobody receives; :meth:`observe` renders it later if needed)."""
        result = unpack_step(
            self.post_step(action), scene=type(self).__name__, hook="post_step", finite=self.check_finite
        )
        self._check_obs(result[0], "post_step")
        if self.camera_rig is None or not observe:
            return result
        return (self.observe(result[0]), *result[1:])

    @property
    def _hooks_obs_space(self) -> spaces.Space:
        """The space the hooks' observations are checked against (without the cameras' images)."""
        return self.observation_space if self.camera_rig is None else self.state_space

    def _check_obs(self, obs: Any, hook: str) -> None:
        scene = type(self).__name__
        check_observation(self._hooks_obs_space, obs, scene=scene, hook=hook, bounds=self.check_obs_bounds)
        if self.check_finite:
            check_finite_obs(obs, scene=scene, hook=hook)

    def substep(self) -> None:
        """Advance the physics by one ``model.opt.timestep``."""
        mujoco.mj_step(self.model, self.data)
        if self._viewer is not None:
            self._viewer.sync(max_fps=60.0)  # real-time mode drives substeps, not step()

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, dict[str, Any]]:
        """One control tick: ``(obs, reward, terminated, info)``."""
        self.prepare_step(action)
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        result = self.finish_tick(action)
        if self._viewer is not None:
            self._viewer.sync()
        return result

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Set generalized positions and velocities and recompute derived quantities."""
        self.data.qpos[:] = qpos
        self.data.qvel[:] = qvel
        if self.model.na == 0:
            self.data.act[:] = 0
        mujoco.mj_forward(self.model, self.data)

    def render(self) -> np.ndarray | None:
        """rgb_array: an RGB frame (uint8, height x width x 3) of the current state, offscreen.
        human: draw the current state in the sim's viewer window; returns None."""
        if self._viewer is not None:
            self._viewer.sync()  # render_mode="human": draw in the sim's viewer window
            return None
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = cheap_renderer(self.model, self.width, self.height, quality=bool(self.render_quality))
        camera = self.default_camera if self.default_camera is not None else -1
        self._renderer.update_scene(self.data, camera=camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        """Release the renderers. Called once when the sim process stops."""
        if self.camera_rig is not None:
            self.camera_rig.close()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
