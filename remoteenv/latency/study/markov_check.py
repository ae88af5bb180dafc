"""Is the action buffer plus alpha Markov for the action in force? Checked on the engine.

Agent side, no physics: :class:`remoteenv.wire.delays.delay_line.LockStepDelays`
(the engine the sim steps with) runs ``steps`` steps of one random delay
model (by default the newest-due rule and no observation delay; ``rule``
and ``obs_model`` choose the delivery rule of both directions and a random
observation delay), each action labelled with the step that sent it. After
every step ``t`` the posterior
:func:`remoteenv.wire.delays.in_force.in_force_posterior` predicts, from
alpha and omega alone (what ``ActionHistory(..., include_alpha=True,
include_obs_delay=True)`` shows beside the buffer), which action will be in
force during each tick ``t + h``, ``h = 1 .. high + 1``; the engine then says
which one was. The prediction depends only on ``(alpha, omega, h)``, so each
``(alpha, omega, h, action)`` is one predicted probability with its measured
frequency; these are pooled into probability bins of width 0.1 (weighted by
their counts), and the check passes when the frequency is within
``tolerance`` of the prediction in every bin that holds at least
:data:`MIN_PREDICTIONS` predictions (sparser ones are listed, not judged). A posterior that missed
information the delays carry (past alphas, say, or the delivery rule) would
show here as a gap.

Run it as a script; its output for the study's models is
``docs/latency/markov_check.json``::

    python -m remoteenv.latency.study.markov_check --out docs/latency/markov_check.json
    python -m remoteenv.latency.study.markov_check --rules newest,in_order --obs-delays none,U(0:4)

Runs in the agent process.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

import numpy as np

from remoteenv.latency.study.design import random_model
from remoteenv.wire.delays.channel_rules import NEWEST, ChannelRules
from remoteenv.wire.delays.delay_line import LockStepDelays
from remoteenv.wire.delays.in_force import delay_pmf, in_force_posterior

#: The study's random models (``StudyConfig.random_delays``' default).
MODELS = ("U(4,8)", "U(6,10)", "U(8,16)", "U(0,16)")
#: Largest allowed |measured frequency - predicted probability| in any bin.
TOLERANCE = 0.02
#: Probability bins: [0, 0.1), [0.1, 0.2), ..., [0.9, 1].
BINS = 10
#: A bin is judged only with at least this many predictions; sparser bins
#: (states seen a few times, e.g. the first steps of the episode while the
#: reset observation is still returned) are listed but their sampling error
#: alone exceeds the tolerance.
MIN_PREDICTIONS = 2000


def in_force_steps(model: str, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(alpha, sent)`` per tick ``1 .. steps`` of one long episode on the engine:
    the age of the action in force and the step that sent it (0: the default)."""
    alpha, _, sent = engine_steps(model, steps, seed)
    return alpha, sent


def engine_steps(
    model: str, steps: int, seed: int, obs_model: str | None = None, rule: str = NEWEST
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(alpha, omega, sent)`` per step ``1 .. steps`` of one long episode on the
    engine (``rule`` both ways, observation delay ``obs_model``): the age of the
    action in force during the returned observation's tick, that observation's
    age, and the step that sent the action in force during tick ``t`` (0: the default)."""
    rules = ChannelRules(action_delivery=rule, obs_delivery=rule)
    obs_delay = 0 if obs_model is None else random_model(obs_model)
    engine = LockStepDelays(action_delay=random_model(model), obs_delay=obs_delay, rules=rules)
    engine.reset(obs=0, sim_time=0.0, default_action=0, seed=seed)
    alpha = np.zeros(steps + 1, dtype=np.int64)
    omega = np.zeros(steps + 1, dtype=np.int64)
    sent = np.zeros(steps + 1, dtype=np.int64)
    for t in range(1, steps + 1):
        _, sent[t] = engine.apply(t)
        _, delays = engine.observe(t, 0.0)
        alpha[t] = delays.obs_action_delay_ticks
        omega[t] = delays.obs_delay_ticks
    return alpha, omega, sent


def calibration(
    model: str,
    steps: int = 200_000,
    seed: int = 0,
    posterior: Any = in_force_posterior,
    *,
    obs_model: str | None = None,
    rule: str = NEWEST,
) -> dict[str, Any]:
    """The calibration of the buffer + alpha (+ omega) ``posterior`` on ``model``
    under ``rule`` and observation delay ``obs_model`` (see the module docs).
    ``posterior(pmf, alpha, horizon)`` is called with ``obs_age=omega`` and
    ``rule=rule`` too unless both are the defaults."""
    spec = random_model(model)
    pmf = delay_pmf(spec)
    horizon = int(spec.high) + 1
    alpha, omega, sent = engine_steps(model, steps, seed, obs_model, rule)
    predicted: list[float] = []
    measured: list[float] = []
    counts: list[int] = []
    last = steps - horizon  # every step t <= last sees all its horizons
    states = sorted({(int(a), int(w)) for a, w in zip(alpha[1 : last + 1], omega[1 : last + 1])})
    for a, w in states:
        ts = np.flatnonzero((alpha[: last + 1] == a) & (omega[: last + 1] == w))
        ts = ts[ts >= 1]
        if obs_model is None and rule == NEWEST:
            buffered, future = posterior(pmf, a, horizon)
        else:
            buffered, future = posterior(pmf, a, horizon, obs_age=w, rule=rule)
        for h in range(1, horizon + 1):
            offset = sent[ts + h] - ts  # <= 0: the buffered action of age -offset; > 0: future step t + offset
            for age in range(buffered.shape[1]):
                predicted.append(float(buffered[h - 1, age]))
                measured.append(float(np.mean(offset == -age)))
                counts.append(len(ts))
            for j in range(1, h + 1):
                predicted.append(float(future[h - 1, j - 1]))
                measured.append(float(np.mean(offset == j)))
                counts.append(len(ts))
    p, f, n = np.array(predicted), np.array(measured), np.array(counts, dtype=np.float64)
    which = np.minimum((p * BINS).astype(int), BINS - 1)
    bins: list[dict[str, Any]] = []
    for b in range(BINS):
        inside = which == b
        if not inside.any():
            continue
        weight = n[inside]
        mean_p = float(np.average(p[inside], weights=weight))
        freq = float(np.average(f[inside], weights=weight))
        bins.append(
            {
                "bin": [b / BINS, (b + 1) / BINS],
                "predictions": int(weight.sum()),
                "mean_predicted": mean_p,
                "frequency": freq,
                "gap": abs(freq - mean_p),
                "judged": bool(weight.sum() >= MIN_PREDICTIONS),
            }
        )
    worst = max(float(b["gap"]) for b in bins if b["judged"])
    return {
        "model": model,
        "rule": rule,
        "obs_delay": obs_model,
        "steps": steps,
        "seed": seed,
        "horizon_ticks": horizon,
        "bins": bins,
        "worst_gap": worst,
        "tolerance": TOLERANCE,
        "calibrated": worst <= TOLERANCE,
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--models", default=",".join(m.replace(",", ":") for m in MODELS), help="e.g. U(6:10),U(0:16)")
    parser.add_argument("--steps", type=int, default=200_000, help="engine steps per model (default 200000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--rules",
        default=NEWEST,
        help="delivery rules (both directions) to check, e.g. newest,in_order (default newest)",
    )
    parser.add_argument(
        "--obs-delays", default="none", help="observation delay models to check, e.g. none,U(0:4) (default none)"
    )
    parser.add_argument("--out", default=None, help="write the results here as JSON")
    args = parser.parse_args(argv)
    results = []
    for rule in args.rules.split(","):
        for obs in args.obs_delays.split(","):
            obs_model = None if obs.strip() == "none" else obs.strip().replace(":", ",")
            for name in args.models.split(","):
                result = calibration(
                    name.strip().replace(":", ","), args.steps, args.seed, obs_model=obs_model, rule=rule.strip()
                )
                results.append(result)
                status = "calibrated" if result["calibrated"] else "NOT calibrated"
                print(
                    f"{result['model']}, {rule.strip()}, observation delay {obs.strip()}: worst bin gap "
                    f"{result['worst_gap']:.4f} over {len(result['bins'])} bins: {status}"
                )
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"tolerance": TOLERANCE, "results": results}, f, indent=1)
            f.write("\n")
    return 0 if all(r["calibrated"] for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
