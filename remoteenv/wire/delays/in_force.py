"""Which action will be in force: the posterior an agent can compute from its
action buffer and alpha, under i.i.d. action delays and the newest-due rule.

Pure numbers, no physics; both processes may use it. The setting is that of
:mod:`remoteenv.wire.delays.delay_line` with ``action_delivery="newest"``
and no observation delay: after step ``t`` the agent holds the actions it
sent with steps ``t - k + 1 .. t`` (its buffer) and alpha, the age of the
action in force during tick ``t`` (``info["obs_action_delay_ticks"]``), so
the action in force is the one sent at step ``s* = t - alpha``. Knowing that
and nothing of the delays drawn, the agent knows exactly this about them:
every action sent after ``s*`` had not arrived by tick ``t``
(``d_s > t - s``), and nothing else (the delays are independent; what older
actions did no longer matters, since none can override ``s*``). So the
delays of the actions sent at ages ``a = 0 .. alpha - 1`` are independent and
each follows the model truncated to ``d > a``; actions sent after ``t`` are
not yet drawn.

During tick ``t + h`` (``h >= 1``) the newest arrived action is in force. An
action of age ``a < alpha`` has arrived by then with probability
``P(a < d <= a + h) / P(d > a)``; the action of age ``alpha`` has arrived for
sure; the action the agent will send at step ``t + j`` (``1 <= j <= h``) has
arrived with probability ``P(d <= h - j)``. The probability that a given
action is in force is that it arrived and every newer one did not.

This is the RDMDP's point (Bouteiller et al. 2021): with alpha, the
buffer's in-force action is Markov; ``docs/latency.md`` shows the
calibration on the engine itself (:mod:`remoteenv.latency.study.markov_check`).
"""

from __future__ import annotations

import numpy as np

from remoteenv.wire.delays.delay_specs import TICKS, Categorical, Constant, DelaySpec, Uniform, as_delay


def delay_pmf(spec: DelaySpec | int) -> np.ndarray:
    """``pmf[d]``: the probability of an action delay of ``d`` ticks, ``d = 0 .. spec.max``.

    For :class:`Constant`, :class:`Uniform` and :class:`Categorical` specs in
    ticks; a :class:`~remoteenv.wire.delays.delay_specs.Trace` is not i.i.d. and raises ``TypeError``."""
    spec = as_delay(spec, TICKS)
    if spec.unit != TICKS:
        raise ValueError(f"delay_pmf needs a delay in ticks, got {spec!r}")
    pmf = np.zeros(int(spec.max) + 1)
    if isinstance(spec, Constant):
        pmf[int(spec.value)] = 1.0
    elif isinstance(spec, Uniform):
        pmf[int(spec.low) : int(spec.high) + 1] = 1.0 / (int(spec.high) - int(spec.low) + 1)
    elif isinstance(spec, Categorical):
        for value, prob in zip(spec.values, spec.probs):
            pmf[int(value)] += prob
    else:
        raise TypeError(f"delay_pmf needs i.i.d. delays (Constant, Uniform or Categorical), got {spec!r}")
    return pmf


def age_survival(pmf: np.ndarray) -> np.ndarray:
    """``P(alpha > a)`` for ``a = 0 .. len(pmf) - 1`` in the stationary regime:
    the action in force is older than ``a`` iff none of the ``a + 1`` newest
    actions has arrived (the one of age ``j`` needs ``d <= j``)."""
    tail = 1.0 - np.cumsum(pmf)  # tail[j] = P(d > j)
    return np.cumprod(np.clip(tail, 0.0, 1.0))


def mean_age(spec: DelaySpec | int) -> float:
    """The stationary mean age (ticks) of the action in force: ``sum_a P(alpha > a)``."""
    return float(age_survival(delay_pmf(spec)).sum())


def in_force_posterior(pmf: np.ndarray, alpha: int, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Which action is in force during ticks ``t + 1 .. t + horizon``, given alpha at tick ``t``.

    Returns ``(buffered, future)``: ``buffered[h - 1, a]`` is the probability
    that the action of age ``a`` (sent at step ``t - a``, ``a = 0 .. alpha``)
    is in force during tick ``t + h``; ``future[h - 1, j - 1]`` that the
    action sent at step ``t + j`` is. Each row sums to 1."""
    if alpha < 0 or horizon < 0:
        raise ValueError(f"in_force_posterior needs alpha >= 0 and horizon >= 0, got {alpha}, {horizon}")
    cdf = np.cumsum(pmf)

    def p_le(x: int) -> float:  # P(d <= x)
        return 0.0 if x < 0 else float(cdf[min(x, len(cdf) - 1)])

    buffered = np.zeros((horizon, alpha + 1))
    future = np.zeros((horizon, horizon))
    for h in range(1, horizon + 1):
        # Newest first: the future actions t + h .. t + 1, then ages 0 .. alpha.
        none_newer = 1.0
        for j in range(h, 0, -1):
            arrived = p_le(h - j)
            future[h - 1, j - 1] = none_newer * arrived
            none_newer *= 1.0 - arrived
        for a in range(alpha + 1):
            if a == alpha:
                arrived = 1.0
            else:
                survive = 1.0 - p_le(a)
                arrived = 0.0 if survive <= 0.0 else (p_le(a + h) - p_le(a)) / survive
            buffered[h - 1, a] = none_newer * arrived
            none_newer *= 1.0 - arrived
    return buffered, future
