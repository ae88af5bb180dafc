"""The hexapod's hand-written gait (agent side)."""

from __future__ import annotations

import numpy as np

#: Hexapod legs in actuator order (``lf, lm, lr, rf, rm, rr``): +1 on the left
#: (+y) side, -1 on the right. A positive hip yaw swings a left foot backwards
#: and a right foot forwards.
HEXAPOD_SIDE = np.array([1.0, 1.0, 1.0, -1.0, -1.0, -1.0])
#: Gait phase offset of each leg (rad): the tripods {lf, lr, rm} and {lm, rf, rr}
#: are half a cycle apart.
HEXAPOD_PHASE = np.array([0.0, np.pi, 0.0, np.pi, 0.0, np.pi])
#: Where the hexapod's observation holds the torso quaternion (w, x, y, z).
HEXAPOD_QUAT = slice(57, 61)


def hexapod_heading(obs: np.ndarray) -> float:
    """Torso yaw (rad, counter-clockwise from +x seen from above) from a hexapod observation."""
    w, x, y, z = (float(v) for v in np.asarray(obs)[HEXAPOD_QUAT])
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def hexapod_tripod(
    obs: np.ndarray,
    t: float,
    period: float = 0.5,
    stride: float = 0.6,
    lift: float = 0.5,
    knee: float = 0.3,
    heading_gain: float = 2.0,
) -> np.ndarray:
    """Tripod gait along +x for ``remoteenv/Hexapod-v0``: ``Box(-1, 1, (18,))`` action.

    Three legs (one tripod) swing forward in the air while the other three
    push the body forward on the ground, then they swap, once per ``period``
    seconds. ``t`` is the simulated time since the episode's reset (s): it
    sets the gait's phase. ``stride``, ``lift`` and ``knee`` are amplitudes in
    action units (fractions of each joint's half range) for the hip yaw swing,
    the femur lift during the swing and the knee tuck that goes with it. The
    only feedback is on heading: when the torso's yaw (from ``obs``) is off
    +x, the strides on the side it must turn towards shorten and the others
    lengthen, by ``heading_gain`` per rad of yaw (as a fraction of ``stride``).
    """
    phase = 2.0 * np.pi * t / period + HEXAPOD_PHASE
    # Each side's stride, shortened on the side the body must turn towards.
    side_stride = stride * np.clip(1.0 + heading_gain * HEXAPOD_SIDE * hexapod_heading(obs), 0.0, 2.0)
    action = np.empty((6, 3))
    # Foot fore-aft position -cos(phase): forwards while the leg is in the
    # air (sin(phase) > 0), backwards while it pushes on the ground.
    action[:, 0] = HEXAPOD_SIDE * side_stride * np.cos(phase)
    up = np.maximum(np.sin(phase), 0.0)
    action[:, 1] = lift * up
    action[:, 2] = -knee * up
    return np.clip(action.reshape(18), -1.0, 1.0).astype(np.float32)


__all__ = ["HEXAPOD_PHASE", "HEXAPOD_QUAT", "HEXAPOD_SIDE", "hexapod_heading", "hexapod_tripod"]
