"""A scene's MJCF model file, found or refused with the fix in the message.

Runs in the sim process (:class:`~remoteenv.sim.scene.base_env.BaseEnv` loads its model from it).
"""

from __future__ import annotations

import os


def model_file(path: str, scene: str) -> str:
    """``path`` if it names a file; else FileNotFoundError naming the ``scene``
    (its class name), with the fix for a relative path."""
    if os.path.isfile(path):
        return path
    hint = ""
    if not os.path.isabs(path):
        hint = (
            f"; a relative path is looked up from the sim process's working directory ({os.getcwd()}), "
            "which is the agent's, not the scene script's folder: build it from the script's folder, "
            'os.path.join(os.path.dirname(os.path.abspath(__file__)), "model.xml")'
        )
    raise FileNotFoundError(f"{scene}: MJCF model file {path!r} not found{hint}")


__all__ = ["model_file"]
