"""render_mode="human": MuJoCo's own viewer window, opened in the sim process.

Runs in the sim process. The window is :func:`mujoco.viewer.launch_passive`:
it shows the world the sim steps (the simulator's own window, as Blender's
was for blendtorch) and lets the user orbit the camera, but the physics keeps
being driven by the agent's requests. Closing the window does not stop the
sim; the world just stops being drawn.

The viewer needs a display (X11 or Wayland). Without one, GLFW cannot start
and MuJoCo would abort the process with a terse "could not initialize GLFW";
:class:`HumanViewer` checks first and raises :class:`HumanRenderUnavailable`,
whose message names ``render_mode="rgb_array"`` (offscreen, works headless)
as the alternative.
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from typing import Any

import mujoco


class HumanRenderUnavailable(RuntimeError):
    """render_mode="human" was asked for where no window can be opened."""


_ALTERNATIVE = (
    'Use render_mode="rgb_array" instead: it renders offscreen (MUJOCO_GL=egl) and '
    "works without a display; gymnasium.wrappers.RecordVideo turns its frames into video. "
    "Gymnasium's check_env builds an env for every declared render mode, human included: "
    "without a display call check_env(env, skip_render_check=True), or run it under a "
    "virtual display (xvfb-run)."
)


def display_problem() -> str | None:
    """Why no viewer window can be opened here, or None if one can."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display: neither DISPLAY nor WAYLAND_DISPLAY is set"
    if os.environ.get("MUJOCO_GL", "glfw").lower() not in ("glfw", ""):
        return (
            f"MUJOCO_GL={os.environ['MUJOCO_GL']} selects a headless OpenGL backend; "
            "the viewer needs MUJOCO_GL unset or glfw"
        )
    try:
        import glfw
    except Exception as exc:  # the package or its shared library is missing
        return f"GLFW is unavailable ({type(exc).__name__}: {exc})"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ok = glfw.init()
    if not ok:
        return (
            f"GLFW could not connect to the display {os.environ.get('DISPLAY') or os.environ.get('WAYLAND_DISPLAY')!r}"
        )
    glfw.terminate()
    return None


class HumanViewer:
    """A passive MuJoCo viewer on one world's ``model``/``data``.

    Args:
        model, data: the world to show; the viewer reads ``data`` on :meth:`sync`.
        instance: the sim instance index, for the error message.

    Raises:
        HumanRenderUnavailable: no display is available (see :func:`display_problem`).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, instance: int | None = None) -> None:
        problem = display_problem()
        where = "" if instance is None else f" (sim instance {instance}, pid {os.getpid()})"
        if problem is not None:
            raise HumanRenderUnavailable(
                f'render_mode="human" cannot open the MuJoCo viewer{where}: {problem}. {_ALTERNATIVE}'
            )
        import mujoco.viewer

        self._handle: Any = mujoco.viewer.launch_passive(model, data)
        self._last_sync = 0.0

    @property
    def is_running(self) -> bool:
        """False once the user closed the window (or :meth:`close` ran)."""
        return self._handle is not None and self._handle.is_running()

    def sync(self, max_fps: float | None = None) -> None:
        """Draw the current state of ``data`` (no-op once the window is closed).

        With ``max_fps``, skip the redraw if the last one was less than
        ``1 / max_fps`` wall seconds ago (for callers that run at physics rate)."""
        if max_fps is not None:
            now = time.monotonic()
            if now - self._last_sync < 1.0 / max_fps:
                return
            self._last_sync = now
        if self.is_running:
            self._handle.sync()

    def close(self) -> None:
        """Close the window."""
        handle, self._handle = self._handle, None
        if handle is not None:
            handle.close()
