"""Reacher's hand-written controller (agent side)."""

from __future__ import annotations

import numpy as np

#: Reacher arm geometry (m): shoulder-elbow and elbow-fingertip distances.
REACHER_LINKS = (0.1, 0.11)


def reacher_reach(obs: np.ndarray, kp: float = 8.0, kd: float = 0.02) -> np.ndarray:
    """Jacobian-transpose PD control towards the target: ``Box(-1, 1, (2,))`` action.

    obs: ``[cos q0, cos q1, sin q0, sin q1, tx, ty, q0_dot, q1_dot, dx, dy]``
    where ``(dx, dy)`` is fingertip minus target.
    """
    obs = np.asarray(obs, dtype=np.float64)
    q0, q1 = np.arctan2(obs[2], obs[0]), np.arctan2(obs[3], obs[1])
    l0, l1 = REACHER_LINKS
    jac = np.array(
        [
            [-l0 * np.sin(q0) - l1 * np.sin(q0 + q1), -l1 * np.sin(q0 + q1)],
            [l0 * np.cos(q0) + l1 * np.cos(q0 + q1), l1 * np.cos(q0 + q1)],
        ]
    )
    action = jac.T @ (-kp * obs[8:10]) - kd * obs[6:8]
    return np.clip(action, -1.0, 1.0).astype(np.float32)


__all__ = ["REACHER_LINKS", "reacher_reach"]
