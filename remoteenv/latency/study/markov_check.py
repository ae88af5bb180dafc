"""Is the action buffer plus alpha Markov for the action in force? Checked on the engine.

Agent side, no physics: :class:`remoteenv.wire.delays.delay_line.LockStepDelays`
(the engine the sim steps with) runs ``steps`` steps of one random delay
model (newest-due rule, no observation delay), each action labelled with the
step that sent it. After every step ``t`` the posterior
:func:`remoteenv.wire.delays.in_force.in_force_posterior` predicts, from
alpha alone (what ``ActionHistory(..., include_alpha=True)`` shows beside the
buffer), which action will be in force during each tick ``t + h``, ``h = 1 ..
high + 1``; the engine then says which one was. The prediction depends only on
``(alpha, h)``, so each ``(alpha, h, action)`` is one predicted probability
with its measured frequency; these are pooled into probability bins of width
0.1 (weighted by their counts), and the check passes when the frequency is
within ``tolerance`` of the prediction in every bin. A posterior that missed
information the delays carry (past alphas, say) would show here as a gap.

Run it as a script; its output for the study's models is
``docs/latency/markov_check.json``::

    python -m remoteenv.latency.study.markov_check --out docs/latency/markov_check.json

Runs in the agent process.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

import numpy as np

from remoteenv.latency.study.design import random_model
from remoteenv.wire.delays.delay_line import LockStepDelays
from remoteenv.wire.delays.in_force import delay_pmf, in_force_posterior

#: The study's random models (``StudyConfig.random_delays``' default).
MODELS = ("U(4,8)", "U(6,10)", "U(8,16)", "U(0,16)")
#: Largest allowed |measured frequency - predicted probability| in any bin.
TOLERANCE = 0.02
#: Probability bins: [0, 0.1), [0.1, 0.2), ..., [0.9, 1].
BINS = 10


def in_force_steps(model: str, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(alpha, sent)`` per tick ``1 .. steps`` of one long episode on the engine:
    the age of the action in force and the step that sent it (0: the default)."""
    engine = LockStepDelays(action_delay=random_model(model))
    engine.reset(obs=0, sim_time=0.0, default_action=0, seed=seed)
    alpha = np.zeros(steps + 1, dtype=np.int64)
    sent = np.zeros(steps + 1, dtype=np.int64)
    for t in range(1, steps + 1):
        _, sent[t] = engine.apply(t)
        _, delays = engine.observe(t, 0.0)
        alpha[t] = delays.obs_action_delay_ticks
    return alpha, sent


def calibration(model: str, steps: int = 200_000, seed: int = 0, posterior: Any = in_force_posterior) -> dict[str, Any]:
    """The calibration of the buffer + alpha ``posterior`` on ``model`` (see the module docs)."""
    spec = random_model(model)
    pmf = delay_pmf(spec)
    horizon = int(spec.high) + 1
    alpha, sent = in_force_steps(model, steps, seed)
    predicted: list[float] = []
    measured: list[float] = []
    counts: list[int] = []
    last = steps - horizon  # every step t <= last sees all its horizons
    for a in np.unique(alpha[1 : last + 1]):
        ts = np.flatnonzero(alpha[: last + 1] == a)
        ts = ts[ts >= 1]
        buffered, future = posterior(pmf, int(a), horizon)
        for h in range(1, horizon + 1):
            offset = sent[ts + h] - ts  # <= 0: the buffered action of age -offset; > 0: future step t + offset
            for age in range(int(a) + 1):
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
            }
        )
    worst = max(float(b["gap"]) for b in bins)
    return {
        "model": model,
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
    parser.add_argument("--out", default=None, help="write the results here as JSON")
    args = parser.parse_args(argv)
    results = []
    for name in args.models.split(","):
        result = calibration(name.strip().replace(":", ","), args.steps, args.seed)
        results.append(result)
        status = "calibrated" if result["calibrated"] else "NOT calibrated"
        print(f"{result['model']}: worst bin gap {result['worst_gap']:.4f} over {len(result['bins'])} bins: {status}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"tolerance": TOLERANCE, "results": results}, f, indent=1)
            f.write("\n")
    return 0 if all(r["calibrated"] for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
