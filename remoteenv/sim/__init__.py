"""Code that runs in the sim process, grouped by concept.

- :mod:`remoteenv.sim.scene`: the contract a scene subclasses (:class:`BaseEnv`,
  :class:`BatchResult`), its cameras, its checks and its viewer;
- :mod:`remoteenv.sim.stepping`: how worlds advance (lock-step, real time,
  batched physics, :func:`stacked` views for batched hooks);
- :mod:`remoteenv.sim.transport`: how requests arrive (channels, peers,
  drivers, limits, the shared region);
- :mod:`remoteenv.sim.serving`: the server loop and its commands;
- :mod:`remoteenv.sim.process`: the process's life (logging, orphan watch,
  pacing, the zygote);
- :mod:`remoteenv.sim.scene_main` and :mod:`remoteenv.sim.publisher`: the
  entry points a sim process runs.

A scene imports what it needs from here: ``from remoteenv.sim import BaseEnv,
BatchResult, run_scene, stacked``; a scene observing through cameras also
``Camera`` and ``camera_observation`` (or ``CameraObservation``).
"""

from remoteenv.sim.scene.base_env import BaseEnv
from remoteenv.sim.scene.batch_result import BatchResult
from remoteenv.sim.scene.camera_rig import CameraSetupError
from remoteenv.sim.scene.cameras import Camera, CameraObservation, camera_observation
from remoteenv.sim.scene_main import run_scene
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.sim.stepping.batch_worlds import stacked

__all__ = [
    "BaseEnv",
    "BatchResult",
    "Camera",
    "CameraObservation",
    "CameraSetupError",
    "RemoteControlledAgent",
    "camera_observation",
    "run_scene",
    "stacked",
]
