"""Which action will be in force: the posterior an agent can compute from its
action buffer, alpha and omega, under i.i.d. action delays and either delivery rule.

Pure numbers, no physics; both processes may use it. The setting is that of
:mod:`remoteenv.wire.delays.delay_line`. After step ``t`` the agent holds the
actions it sent with steps ``t - k + 1 .. t`` (its buffer), the returned
observation's age omega (``info["obs_delay_ticks"]``; 0 without an
observation delay) and alpha, the age of the action in force during that
observation's tick ``m = t - omega`` (``info["obs_action_delay_ticks"]``):
the action in force at tick ``m`` is the one sent at step ``s* = m - alpha``,
of age ``alpha + omega`` now. Knowing that and nothing of the delays drawn:

- ``action_delivery="newest"`` (``A_s = s + d_s``): every action sent after
  ``s*`` and by tick ``m`` had not arrived by ``m`` (``d_s > m - s``), and
  nothing else is known (the delays are independent; older actions can no
  longer act). So the delays of the actions of ages ``omega .. alpha + omega
  - 1`` each follow the model truncated to ``d > age - omega``; those of
  ages ``0 .. omega - 1`` (sent after tick ``m``) the model itself.
- ``action_delivery="in_order"`` (``A_s = max(s + d_s, A_{s-1})``): arrivals
  are ordered, so at tick ``m`` only the first action after ``s*`` is known
  not to have arrived (``d > m - s* - 1``, when it was sent by ``m``); that
  implies the rest. Each later action arrives at ``max(s + d_s, A_{s-1})``,
  so ``A_s <= x`` iff the first one's and every later one's own
  ``s + d_s <= x``.

During tick ``t + h`` the newest arrived action is in force: under
``"newest"`` the arrival events are independent, and an action is in force
when it has arrived and no newer one has; under ``"in_order"`` the action
sent at ``s`` is in force when ``A_s <= t + h < A_{s+1}``. The action the
agent will send at step ``t + j`` has arrived by tick ``t + h`` with
probability ``P(d <= h - j)`` (before the chain's order, under
``"in_order"``). The observation delivery rule does not matter: observation
delays are independent of action delays.

This is the RDMDP's point (Bouteiller et al. 2021): with alpha and omega,
the buffer's in-force action is Markov; ``docs/latency.md`` shows the
calibration on the engine itself (:mod:`remoteenv.latency.study.markov_check`).
"""

from __future__ import annotations

import numpy as np

from remoteenv.wire.delays.channel_rules import IN_ORDER, NEWEST
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


def age_survival(pmf: np.ndarray, rule: str = NEWEST) -> np.ndarray:
    """``P(alpha > a)`` for ``a = 0 .. len(pmf) - 1`` in the stationary regime.

    Newest-due: the action in force is older than ``a`` iff none of the
    ``a + 1`` newest actions has arrived (the one of age ``j`` needs ``d <= j``).
    In order: iff the action of age ``a`` has not arrived, i.e. not every
    action of age ``j >= a`` has its own ``d <= j`` (arrivals keep their order)."""
    cdf = np.clip(np.cumsum(pmf), 0.0, 1.0)  # cdf[j] = P(d <= j)
    if rule == IN_ORDER:
        all_older_in = np.cumprod(cdf[::-1])[::-1]  # prod over j >= a of P(d <= j)
        return 1.0 - all_older_in
    return np.cumprod(1.0 - cdf)


def mean_age(spec: DelaySpec | int, rule: str = NEWEST) -> float:
    """The stationary mean age (ticks) of the action in force under ``rule``: ``sum_a P(alpha > a)``."""
    return float(age_survival(delay_pmf(spec), rule).sum())


def in_force_posterior(
    pmf: np.ndarray,
    alpha: int,
    horizon: int,
    *,
    obs_age: int = 0,
    rule: str = NEWEST,
    from_obs: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Which action is in force during ticks ``t + 1 .. t + horizon``, given alpha
    at the returned observation's tick ``m = t - obs_age`` (see the module docs).

    Returns ``(buffered, future)``: ``buffered[i, a]`` is the probability that
    the action of age ``a`` (sent at step ``t - a``, ``a = 0 .. alpha +
    obs_age``) is in force during row ``i``'s tick; ``future[i, j - 1]`` that
    the action sent at step ``t + j`` is. Row ``i`` is tick ``t + 1 + i``;
    with ``from_obs`` the rows start at the observation's next tick instead,
    ``m + 1 .. t + horizon`` (``obs_age + horizon`` rows: what happened since
    the observation, then what will). Each row sums to 1. ``rule``: the action
    delivery rule, ``"newest"`` or ``"in_order"``."""
    if alpha < 0 or horizon < 0 or obs_age < 0:
        raise ValueError(f"in_force_posterior needs alpha, horizon and obs_age >= 0, got {alpha}, {horizon}, {obs_age}")
    if rule not in (NEWEST, IN_ORDER):
        raise ValueError(f"in_force_posterior: rule must be {NEWEST!r} or {IN_ORDER!r}, got {rule!r:.40}")
    cdf = np.cumsum(pmf)

    def p_le(x: int) -> float:  # P(d <= x)
        return 0.0 if x < 0 else float(cdf[min(x, len(cdf) - 1)])

    top = alpha + obs_age  # the age of the action in force at tick m
    first = 1 - obs_age if from_obs else 1
    rows = range(first, horizon + 1)
    buffered = np.zeros((len(rows), top + 1))
    future = np.zeros((len(rows), horizon))
    for i, h in enumerate(rows):
        # The actions newer than s*, oldest first, with the chance each has
        # arrived (on its own) by tick t + h: ages top - 1 .. 0, then t + 1 ...
        arrived: list[float] = []
        for a in range(top - 1, -1, -1):
            known = a >= obs_age and (rule == NEWEST or a == top - 1)  # sent by m, not arrived by m
            if known:
                survive = 1.0 - p_le(a - obs_age)
                arrived.append(0.0 if survive <= 0.0 else (p_le(a + h) - p_le(a - obs_age)) / survive)
            else:
                arrived.append(p_le(a + h))
        arrived += [p_le(h - j) for j in range(1, max(h, 0) + 1)]
        in_force = _newest(arrived) if rule == NEWEST else _in_order(arrived)
        # in_force[0] is s* (age top); then ages top - 1 .. 0; then the future actions.
        buffered[i, ::-1] = in_force[: top + 1]
        future[i, : len(in_force) - top - 1] = in_force[top + 1 :]
    return buffered, future


def _newest(arrived: list[float]) -> list[float]:
    """In force under the newest rule: arrived, and no newer one arrived (s* first, then ``arrived``'s)."""
    out = [0.0] * (len(arrived) + 1)
    none_newer = 1.0
    for i in range(len(arrived) - 1, -1, -1):
        out[i + 1] = none_newer * arrived[i]
        none_newer *= 1.0 - arrived[i]
    out[0] = none_newer
    return out


def _in_order(arrived: list[float]) -> list[float]:
    """In force in order: the chain has reached it and not the next one (s* first, then ``arrived``'s)."""
    out = []
    reached = 1.0  # P(A_s <= x) along the chain; s* has arrived
    for p in arrived:
        out.append(reached * (1.0 - p))
        reached *= p
    out.append(reached)
    return out
