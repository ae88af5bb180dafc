"""CartPole controllers that predict through the actions in flight (agent side).

Under an action delay the action chosen now acts on a later state, after
the actions already sent have taken effect. These controllers roll a MuJoCo
copy of the CartPole scene's model through those actions before applying
the shipped LQR's gains (:mod:`remoteenv.scene_controllers.cartpole`):
:class:`CartpolePredictor` for known actions in flight (an
:class:`~remoteenv.latency.action_history.ActionHistory` observation),
:class:`CartpoleExpectedPredictor` for random delays (the expected action
in force, from the buffer and alpha), :class:`CartpoleHoldPredictor` for an
agent that acts once per real-time step.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from remoteenv.scene_controllers.cartpole import (
    CARTPOLE_DT,
    CARTPOLE_GAINS,
    CARTPOLE_OBS,
    CARTPOLE_SOFT_GAINS,
    cartpole_model_path,
)


class CartpolePredictor:
    """LQR for continuous CartPole that looks through the actions in flight.

    Under an action delay of ``k`` ticks the action chosen now acts on the
    state ``k`` ticks from now, after the ``k`` actions already sent have
    taken effect. This controller puts the (delayed) observation into a
    MuJoCo copy of the scene's own model (``cartpole.xml`` of the installed
    ``remoteenv.scenes.cartpole``), rolls it forward one control tick per
    action in flight (each held for :data:`CARTPOLE_DT` s, as the sim holds
    it), and applies :func:`~remoteenv.scene_controllers.cartpole.cartpole_continuous`'s gains to the predicted
    state. With no action in flight it is :func:`~remoteenv.scene_controllers.cartpole.cartpole_continuous`.

    Called on an observation of :class:`remoteenv.latency.action_history.ActionHistory`
    (``[x, x_dot, theta, theta_dot, a_{t-k+1}, ..., a_t]``, oldest first; the
    zeros after a reset are the default action, zero force), it takes the
    ``k`` actions from there: in lock-step with ``action_delay=k`` and
    ``ActionHistory(env, k)`` those are exactly the actions in force during
    the next ``k`` ticks, so the prediction is exact up to the observation's
    float32 rounding.

    Args:
        gains: state-feedback gains on ``[x, x_dot, theta, theta_dot]``.
    """

    def __init__(self, gains: np.ndarray = CARTPOLE_GAINS) -> None:
        import mujoco

        self._mujoco = mujoco
        self.gains = np.asarray(gains, dtype=np.float64)
        self.model = mujoco.MjModel.from_xml_path(cartpole_model_path())
        self.data = mujoco.MjData(self.model)
        #: Physics substeps per control tick.
        self.frame_skip = round(CARTPOLE_DT / float(self.model.opt.timestep))

    def predict(self, obs: np.ndarray, in_flight: Sequence[Any] | np.ndarray = ()) -> np.ndarray:
        """The state ``[x, x_dot, theta, theta_dot]`` once the actions ``in_flight``
        (oldest first, each a ``Box(-1, 1, (1,))`` action) have been in force
        for one control tick each, starting from ``obs``."""
        mujoco, data = self._mujoco, self.data
        state = np.asarray(obs, dtype=np.float64).reshape(-1)[:CARTPOLE_OBS]
        mujoco.mj_resetData(self.model, data)
        data.qpos[:] = state[[0, 2]]
        data.qvel[:] = state[[1, 3]]
        for action in in_flight:
            data.ctrl[0] = float(np.clip(np.asarray(action, dtype=np.float64).reshape(-1)[0], -1.0, 1.0))
            mujoco.mj_step(self.model, data, nstep=self.frame_skip)
        return np.array([data.qpos[0], data.qvel[0], data.qpos[1], data.qvel[1]])

    def act(self, obs: np.ndarray, in_flight: Sequence[Any] | np.ndarray = ()) -> np.ndarray:
        """:attr:`gains` applied to the state :meth:`predict` returns (a ``Box(-1, 1, (1,))`` action)."""
        u = float(np.dot(self.gains, self.predict(obs, in_flight)))
        return np.array([np.clip(u, -1.0, 1.0)], dtype=np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The action for an :class:`~remoteenv.latency.action_history.ActionHistory` observation (any ``k``)."""
        flat = np.asarray(obs).reshape(-1)
        return self.act(flat[:CARTPOLE_OBS], flat[CARTPOLE_OBS:].reshape(-1, 1))


class CartpoleExpectedPredictor:
    """:class:`CartpolePredictor` for random action delays: it rolls the model
    through the *expected* actions in force.

    Called on an :class:`~remoteenv.latency.action_history.ActionHistory` observation with
    ``include_alpha=True`` (``[x, x_dot, theta, theta_dot, a_{t-k+1} .. a_t,
    alpha]``, ``k >= max delay + 1``: what a history + alpha policy sees, and
    nothing else), in lock-step with i.i.d. action delays ``delay`` (ticks),
    the newest-due rule and no observation delay. For each of the next
    ``horizon`` ticks it takes the posterior of which action is in force
    (:func:`remoteenv.wire.delays.in_force.in_force_posterior`: from the
    buffer and alpha), forms the expected action (an action not yet sent
    counts as the newest one sent, ``a_t``), holds it for one control tick
    in a MuJoCo copy of the scene's model starting from the observation,
    and applies its gains (by default :data:`CARTPOLE_SOFT_GAINS`) to the
    predicted state.

    Args:
        delay: the action delay model (ticks; Constant, Uniform or Categorical).
        horizon: ticks to predict; default the stationary mean age of the
            action in force under ``delay``, rounded
            (:func:`remoteenv.wire.delays.in_force.mean_age`): about when the
            action chosen now will be the one acting.
        gains: state-feedback gains on ``[x, x_dot, theta, theta_dot]``.
    """

    def __init__(self, delay: Any, horizon: int | None = None, gains: np.ndarray = CARTPOLE_SOFT_GAINS) -> None:
        from remoteenv.wire.delays.in_force import delay_pmf, in_force_posterior, mean_age

        self.pmf = delay_pmf(delay)
        self.horizon = int(round(mean_age(delay))) if horizon is None else int(horizon)
        self.predictor = CartpolePredictor(gains)
        self._posterior = in_force_posterior
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def expected_actions(self, buffer: np.ndarray, alpha: int) -> np.ndarray:
        """The expected action in force during each of the next :attr:`horizon`
        ticks, from the ``buffer`` (oldest first, newest ``a_t`` last) and alpha."""
        buffer = np.asarray(buffer, dtype=np.float64).reshape(-1)
        if not 0 <= alpha < len(buffer):
            raise ValueError(f"alpha {alpha} needs a buffer of more than {alpha} actions, got {len(buffer)}")
        if alpha not in self._cache:
            self._cache[alpha] = self._posterior(self.pmf, alpha, self.horizon)
        buffered, future = self._cache[alpha]
        by_age = buffer[::-1][: alpha + 1]  # by_age[a]: the action of age a
        return buffered @ by_age + future.sum(axis=1) * buffer[-1]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        flat = np.asarray(obs, dtype=np.float64).reshape(-1)
        alpha = int(round(flat[-1]))
        expected = self.expected_actions(flat[CARTPOLE_OBS:-1], alpha)
        return self.predictor.act(flat[:CARTPOLE_OBS], expected.reshape(-1, 1))


class CartpoleHoldPredictor:
    """:class:`CartpolePredictor` for an agent that acts once per elastic step
    (real time, or its lock-step twin: :mod:`remoteenv.latency.twin`).

    While such an agent thinks, its previous action stays in force; the new
    one takes effect some latency later. This policy remembers the action it
    returned last and predicts ``horizon_ticks`` control ticks of it before
    applying the gains: set the horizon to the latency you expect (in whole
    ticks). Called on the plain observation; :meth:`reset` at each episode
    start (the previous action is then the default one, zero force).
    """

    def __init__(self, horizon_ticks: int, predictor: CartpolePredictor | None = None) -> None:
        if isinstance(horizon_ticks, bool) or not isinstance(horizon_ticks, int) or horizon_ticks < 0:
            raise ValueError(f"horizon_ticks must be a whole number of ticks >= 0, got {horizon_ticks!r}")
        self.predictor = predictor or CartpolePredictor()
        self.horizon_ticks = horizon_ticks
        self._last = np.zeros(1, dtype=np.float32)

    def reset(self) -> None:
        """Forget the previous action (a new episode starts with zero force)."""
        self._last = np.zeros(1, dtype=np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self._last = self.predictor.act(obs, [self._last] * self.horizon_ticks)
        return self._last


__all__ = ["CartpoleExpectedPredictor", "CartpoleHoldPredictor", "CartpolePredictor"]
