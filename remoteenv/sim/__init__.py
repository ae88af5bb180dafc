"""Code that runs in the sim process: the scene's env, its stepping and the server."""

from remoteenv.sim.base_env import BaseEnv
from remoteenv.sim.scene_main import run_scene
from remoteenv.sim.server import RemoteControlledAgent

__all__ = ["BaseEnv", "RemoteControlledAgent", "run_scene"]
