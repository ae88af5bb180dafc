"""A scene's MJCF model file: found or refused with the fix in the message, then compiled.

Runs in the sim process (:class:`~remoteenv.sim.scene.base_env.BaseEnv` loads
each world's model through :func:`load_model`). A process that builds many
worlds from one file compiles it once: a file whose text refers to no other
file (no ``file=`` attribute, so no include, mesh, texture or height field
from disk) and to no plugin compiles to the same model whatever its path and
whenever it is read, so the first compile of a text is kept and each world
gets a copy of it (``mj_copyModel``: its own arrays, which the scene may
change per world). Compiling Reacher costs ~0.8 ms here, a copy ~0.3 ms;
64 worlds start ~30 ms sooner. The text is read again for every world, so a
scene that rewrites its file between worlds gets what it wrote.
"""

from __future__ import annotations

import copy
import os
import re
from collections import OrderedDict

import mujoco

#: Texts whose compiled model is kept, the most recently used first out last.
CACHE_SIZE = 8
_compiled: OrderedDict[bytes, mujoco.MjModel] = OrderedDict()
#: What makes a compile depend on more than the text: files beside it, plugins.
_REFERS_OUT = re.compile(rb"file\s*=|<\s*plugin\b|<\s*extension\b")


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


def load_model(path: str, scene: str) -> mujoco.MjModel:
    """The model compiled from the MJCF file at ``path`` (found as :func:`model_file`
    finds it), a model of the caller's own: a copy of an earlier compile of the
    same text when the text stands alone (see the module), else compiled now.
    Compile errors are MuJoCo's, as ``MjModel.from_xml_path`` raises them."""
    found = model_file(path, scene)
    text = _read(found)
    kept = _compiled.get(text)
    if kept is not None:
        _compiled.move_to_end(text)
        return copy.copy(kept)
    model = mujoco.MjModel.from_xml_path(found)
    if _REFERS_OUT.search(text) is None and _read(found) == text:  # not rewritten while it compiled
        _compiled[text] = copy.copy(model)
        while len(_compiled) > CACHE_SIZE:
            _compiled.popitem(last=False)
    return model


def _read(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


def forget_models() -> None:
    """Drop every kept compile (tests; a process that wants its memory back)."""
    _compiled.clear()


__all__ = ["CACHE_SIZE", "forget_models", "load_model", "model_file"]
