"""CartPole's hand-written controllers and the model facts they use (agent side)."""

from __future__ import annotations

import importlib
import importlib.resources

import numpy as np

#: State-feedback gains for continuous CartPole, on obs ``[x, x_dot, theta,
#: theta_dot]``, in units of the action (1.0 = 10 N). An infinite-horizon
#: discrete LQR for the MuJoCo model linearized upright at dt = 0.02 s with
#: Q = diag(1, 10, 0.1, 0.1) on [x, theta, x_dot, theta_dot] and R = 1.
CARTPOLE_GAINS = np.array([0.857, 1.048, 6.950, 1.664])


#: Softer gains for random action delays, same units: the same LQR with R =
#: 10. When an action's delay is uncertain by several ticks, the shipped gains
#: (tuned for a known timing) overshoot: :class:`CartpoleExpectedPredictor`
#: held 227 of 500 under Uniform(8, 16) with :data:`CARTPOLE_GAINS`, 500
#: with these (10 evaluation episodes, reset seeds 10000-10009).
CARTPOLE_SOFT_GAINS = np.array([0.283, 0.417, 3.957, 0.986])


def cartpole_continuous(obs: np.ndarray) -> np.ndarray:
    """Balance the pole and centre the cart: ``Box(-1, 1, (1,))`` action."""
    u = float(np.dot(CARTPOLE_GAINS, np.asarray(obs, dtype=np.float64)))
    return np.array([np.clip(u, -1.0, 1.0)], dtype=np.float32)


def cartpole_discrete(obs: np.ndarray) -> int:
    """Bang-bang version of :func:`cartpole_continuous` for ``Discrete(2)``."""
    return int(np.dot(CARTPOLE_GAINS, np.asarray(obs, dtype=np.float64)) > 0.0)


#: Control tick of the CartPole scene (s): ``frame_skip`` substeps of its model's timestep.
CARTPOLE_DT = 0.02
#: Entries of a CartPole observation (and of its state): ``[x, x_dot, theta, theta_dot]``.
CARTPOLE_OBS = 4


def cartpole_model_path() -> str:
    """Path of the CartPole scene's MJCF model in the installed ``remoteenv.scenes.cartpole``."""
    importlib.import_module("remoteenv")  # makes remoteenv.scenes importable from a source checkout too
    return str(importlib.resources.files("remoteenv.scenes.cartpole").joinpath("cartpole.xml"))


__all__ = [
    "CARTPOLE_DT",
    "CARTPOLE_GAINS",
    "CARTPOLE_OBS",
    "CARTPOLE_SOFT_GAINS",
    "cartpole_continuous",
    "cartpole_discrete",
    "cartpole_model_path",
]
