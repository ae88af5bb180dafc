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
from remoteenv.wire.delays.channel_rules import IN_ORDER, NEWEST
from remoteenv.wire.messages.handshake import LOCK_STEP


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
    alpha]``; with an observation delay also ``include_obs_delay=True``,
    ``[..., alpha, omega]``; ``k`` at least
    :func:`~remoteenv.latency.action_history.required_history`: what a history + alpha
    policy sees, and nothing else), in lock-step with i.i.d. action delays
    ``delay`` (ticks) delivered by ``action_delivery``. For each tick from
    the observation's to ``horizon`` ticks from now it takes the posterior of
    which action is in force
    (:func:`remoteenv.wire.delays.in_force.in_force_posterior`: from the
    buffer, alpha and omega), forms the expected action (an action not yet
    sent counts as the newest one sent, ``a_t``), holds it for one control
    tick in a MuJoCo copy of the scene's model starting from the
    observation, and applies its gains (by default
    :data:`CARTPOLE_SOFT_GAINS`) to the predicted state.

    :meth:`for_env` builds it from an env's handshake, and :meth:`check_env`
    refuses, in one line, an env it does not fit (real time, a trace, another
    delay, rule or observation delay, an observation without alpha or omega).

    Args:
        delay: the action delay model (ticks; Constant, Uniform or Categorical).
        horizon: ticks to predict beyond now; default the stationary mean age
            of the action in force under ``delay`` and the rule, rounded
            (:func:`remoteenv.wire.delays.in_force.mean_age`): about when the
            action chosen now will be the one acting.
        gains: state-feedback gains on ``[x, x_dot, theta, theta_dot]``.
        action_delivery: the env's ``action_delivery``, ``"newest"`` or ``"in_order"``.
        obs_delay: the env's observation delay model (ticks; 0: none).
    """

    def __init__(
        self,
        delay: Any,
        horizon: int | None = None,
        gains: np.ndarray = CARTPOLE_SOFT_GAINS,
        *,
        action_delivery: str = NEWEST,
        obs_delay: Any = 0,
    ) -> None:
        from remoteenv.wire.delays.delay_specs import TICKS, as_delay
        from remoteenv.wire.delays.in_force import delay_pmf, in_force_posterior, mean_age

        if action_delivery not in (NEWEST, IN_ORDER):
            raise ValueError(f"action_delivery must be 'newest' or 'in_order', got {action_delivery!r:.40}")
        self.delay = as_delay(delay, TICKS)
        self.pmf = delay_pmf(self.delay)
        self.rule = action_delivery
        self.obs_delay = as_delay(obs_delay, TICKS)
        #: Whether observations carry omega after alpha (there is an observation delay).
        self.with_omega = not self.obs_delay.is_zero
        self.horizon = int(round(mean_age(self.delay, self.rule))) if horizon is None else int(horizon)
        self.predictor = CartpolePredictor(gains)
        self._posterior = in_force_posterior
        self._cache: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def expected_actions(self, buffer: np.ndarray, alpha: int, omega: int = 0) -> np.ndarray:
        """The expected action in force during each tick from the observation's
        next one to :attr:`horizon` ticks from now (``omega + horizon`` ticks),
        from the ``buffer`` (oldest first, newest ``a_t`` last), alpha and omega."""
        buffer = np.asarray(buffer, dtype=np.float64).reshape(-1)
        if alpha < 0 or omega < 0 or alpha + omega >= len(buffer):
            raise ValueError(
                f"alpha {alpha} and omega {omega} need a buffer of more than {alpha + omega} actions, got {len(buffer)}"
            )
        key = (alpha, omega)
        if key not in self._cache:
            self._cache[key] = self._posterior(
                self.pmf, alpha, self.horizon, obs_age=omega, rule=self.rule, from_obs=True
            )
        buffered, future = self._cache[key]
        by_age = buffer[::-1][: alpha + omega + 1]  # by_age[a]: the action of age a
        return buffered @ by_age + future.sum(axis=1) * buffer[-1]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        flat = np.asarray(obs, dtype=np.float64).reshape(-1)
        if self.with_omega:
            alpha, omega, buffer = int(round(flat[-2])), int(round(flat[-1])), flat[CARTPOLE_OBS:-2]
        else:
            alpha, omega, buffer = int(round(flat[-1])), 0, flat[CARTPOLE_OBS:-1]
        expected = self.expected_actions(buffer, alpha, omega)
        return self.predictor.act(flat[:CARTPOLE_OBS], expected.reshape(-1, 1))

    @classmethod
    def for_env(
        cls, env: Any, horizon: int | None = None, gains: np.ndarray = CARTPOLE_SOFT_GAINS
    ) -> CartpoleExpectedPredictor:
        """The predictor for ``env``'s delays, rule and observation delay (read from
        its handshake); refused in one line where it does not fit (:meth:`check_env`)."""
        delay, rule, obs_delay = _lock_step_delays(env)
        try:
            predictor = cls(delay, horizon, gains, action_delivery=rule, obs_delay=obs_delay)
        except TypeError as exc:
            raise ValueError(f"CartpoleExpectedPredictor cannot predict this env's delays: {exc}") from None
        predictor.check_env(env)
        return predictor

    def check_env(self, env: Any) -> None:
        """Raise a one-line ValueError if ``env`` is not the setting this predictor
        assumes (see the class docs); return None if it is."""
        delay, rule, obs_delay = _lock_step_delays(env)
        me = "CartpoleExpectedPredictor"
        if delay.to_wire() != self.delay.to_wire():
            raise ValueError(f"{me}: the env's action delay is {delay!r}, the predictor's {self.delay!r}")
        if rule != self.rule:
            raise ValueError(f"{me}: the env delivers actions {rule!r}, the predictor assumes {self.rule!r}")
        if obs_delay.to_wire() != self.obs_delay.to_wire():
            raise ValueError(f"{me}: the env's observation delay is {obs_delay!r}, the predictor's {self.obs_delay!r}")
        history = _find_action_history(env)
        need = int(self.delay.max) + int(self.obs_delay.max) + 1
        if history is None or not history.include_alpha or history.include_latency or history.k < need:
            raise ValueError(
                f"{me} needs ActionHistory(env, k>={need}, include_alpha=True"
                + (", include_obs_delay=True" if self.with_omega else "")
                + ") as the env's outermost feature wrapper, without include_latency"
            )
        if history.include_obs_delay != self.with_omega:
            raise ValueError(
                f"{me}: ActionHistory's include_obs_delay must be {self.with_omega} "
                f"(the env's observation delay is {obs_delay!r})"
            )


def _lock_step_delays(env: Any) -> tuple[Any, str, Any]:
    """``(action delay, action delivery rule, observation delay)`` of a lock-step
    env, from its handshake; a one-line ValueError for a real-time env."""
    from remoteenv.wire.delays.channel_rules import ChannelRules
    from remoteenv.wire.delays.delay_specs import TICKS, Constant, delay_from_wire

    stepping = dict(getattr(env, "unwrapped", env).handshake["stepping"])
    if stepping.get("mode") != LOCK_STEP:
        raise ValueError(
            "CartpoleExpectedPredictor predicts lock-step delays drawn per tick; this env runs in real time, "
            "whose latencies are not (use its exact twin, or lock-step delays)"
        )
    action = stepping.get("action_delay_spec")
    delay = delay_from_wire(action) if action is not None else Constant(int(stepping.get("action_delay", 0)), TICKS)
    obs = stepping.get("obs_delay_spec")
    obs_delay = delay_from_wire(obs) if obs is not None else Constant(0, TICKS)
    rules = ChannelRules.from_wire(stepping["channel"]) if "channel" in stepping else ChannelRules()
    return delay, rules.action_delivery, obs_delay


def _find_action_history(env: Any) -> Any:
    """The outermost :class:`~remoteenv.latency.action_history.ActionHistory` among ``env``'s wrappers (None: none)."""
    from remoteenv.latency.action_history import ActionHistory

    layer = env
    while layer is not None:
        if isinstance(layer, ActionHistory):
            return layer
        layer = getattr(layer, "env", None)
    return None


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
