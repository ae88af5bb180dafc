"""A camera's intrinsics and extrinsics, as the renderer draws its images.

Runs in the sim process (an agent gets them through the scene's
``camera_geometry`` method, ``env.call("camera_geometry")``). OpenCV's
pinhole convention, which most vision code takes:

- ``intrinsics`` ``K`` (3x3): a point ``(X, Y, Z)`` in the camera frame
  (x right, y down, z forward, metres) lands at pixel coordinates
  ``u = fx X / Z + cx``, ``v = fy Y / Z + cy``, where pixel ``(row, col)``
  covers ``[col, col + 1) x [row, row + 1)`` (its centre is at ``+ 0.5``) and
  row 0 is the image's top row, as the images arrive;
- ``cam2world`` (4x4): the camera frame's pose in the world, so a world
  point ``p`` is ``inv(cam2world) @ [p, 1]`` in the camera frame. MuJoCo's
  own camera frame (``data.cam_xmat``: x right, y up, looking along -z) is
  this one turned half a turn about x.

Both come from the world as it is now: ``data.cam_xpos``/``cam_xmat`` (what
the last ``mj_forward`` or ``mj_step`` computed, which is what the renderer
draws from) and the projection MuJoCo's ``mjv_updateCamera`` makes for an
image of this size (``fovy``, or a camera's ``sensorsize`` and focal length).
"""

from __future__ import annotations

import mujoco
import numpy as np

#: MuJoCo's camera frame (x right, y up, z backward) to OpenCV's (x right, y down, z forward).
_MJ_TO_CV = np.diag([1.0, -1.0, -1.0])


def intrinsics(model: mujoco.MjModel, data: mujoco.MjData, camera_id: int, width: int, height: int) -> np.ndarray:
    """``K`` of camera ``camera_id`` for ``width`` x ``height`` images (float64, 3x3).

    Raises ValueError for an orthographic camera (no pinhole matrix)."""
    scene = mujoco.MjvScene(model, maxgeom=0)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
    camera.fixedcamid = camera_id
    mujoco.mjv_updateCamera(model, data, camera, scene)
    gl = scene.camera[0]
    if gl.orthographic:
        raise ValueError(f"camera {model.camera(camera_id).name!r} is orthographic: it has no pinhole intrinsics")
    near, top, bottom, center = gl.frustum_near, gl.frustum_top, gl.frustum_bottom, gl.frustum_center
    # As mjr_render: a frustum width of 0 means the viewport's aspect ratio sets it.
    half_width = gl.frustum_width / 2 if gl.frustum_width else 0.5 * (width / height) * (top - bottom)
    fx = width * near / (2 * half_width)
    fy = height * near / (top - bottom)
    cx = width * (half_width - center) / (2 * half_width)
    cy = height * top / (top - bottom)
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def cam2world(data: mujoco.MjData, camera_id: int) -> np.ndarray:
    """The pose of camera ``camera_id``'s OpenCV frame in the world (float64, 4x4)."""
    pose = np.eye(4)
    pose[:3, :3] = data.cam_xmat[camera_id].reshape(3, 3) @ _MJ_TO_CV
    pose[:3, 3] = data.cam_xpos[camera_id]
    return pose


def camera_geometry(
    model: mujoco.MjModel, data: mujoco.MjData, camera_id: int, width: int, height: int
) -> dict[str, object]:
    """``{"intrinsics": K, "cam2world": pose, "width": width, "height": height}`` of one camera now."""
    return {
        "intrinsics": intrinsics(model, data, camera_id, width, height),
        "cam2world": cam2world(data, camera_id),
        "width": int(width),
        "height": int(height),
    }


__all__ = ["cam2world", "camera_geometry", "intrinsics"]
