"""Hand-written controllers for the shipped scenes (agent side).

Used by the demo, the tests and the examples as fixed, known-good policies.
"""

from __future__ import annotations

import numpy as np

#: State-feedback gains for continuous CartPole, on obs ``[x, x_dot, theta,
#: theta_dot]``, in units of the action (1.0 = 10 N). An infinite-horizon
#: discrete LQR for the MuJoCo model linearized upright at dt = 0.02 s with
#: Q = diag(1, 10, 0.1, 0.1) on [x, theta, x_dot, theta_dot] and R = 1.
CARTPOLE_GAINS = np.array([0.857, 1.048, 6.950, 1.664])


def cartpole_continuous(obs: np.ndarray) -> np.ndarray:
    """Balance the pole and centre the cart: ``Box(-1, 1, (1,))`` action."""
    u = float(np.dot(CARTPOLE_GAINS, np.asarray(obs, dtype=np.float64)))
    return np.array([np.clip(u, -1.0, 1.0)], dtype=np.float32)


def cartpole_discrete(obs: np.ndarray) -> int:
    """Bang-bang version of :func:`cartpole_continuous` for ``Discrete(2)``."""
    return int(np.dot(CARTPOLE_GAINS, np.asarray(obs, dtype=np.float64)) > 0.0)


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
    jac = np.array([
        [-l0 * np.sin(q0) - l1 * np.sin(q0 + q1), -l1 * np.sin(q0 + q1)],
        [l0 * np.cos(q0) + l1 * np.cos(q0 + q1), l1 * np.cos(q0 + q1)],
    ])
    action = jac.T @ (-kp * obs[8:10]) - kd * obs[6:8]
    return np.clip(action, -1.0, 1.0).astype(np.float32)
