"""The acting action's age and the actions that never act, under both delivery rules.

Drives the lock-step delay engine (:class:`remoteenv.delays.LockStepDelays`,
no physics: its rules do not depend on it) for ``--steps`` ticks of one
episode with ``action_delay=Uniform(0, k)`` for each ``k``, under
``action_delivery="newest"`` and ``"in_order"``, and prints per ``k`` the mean
age of the action in force (``info["action_delay_ticks"]`` averaged over the
ticks) and the fraction of the actions sent that never took effect. The table
in ``docs/delays.md`` is this script's output with the defaults.

    python examples/delivery_rules.py [--steps 100000] [--seed 0] [--k 1,2,4,8,16,24,32]
"""

from __future__ import annotations

import argparse

from remoteenv.delays import ChannelRules, LockStepDelays, Uniform


def measure(k: int, rule: str, steps: int, seed: int) -> dict:
    """The engine's own run figures after ``steps`` ticks of ``Uniform(0, k)`` under ``rule``."""
    engine = LockStepDelays(Uniform(0, k), 0, ChannelRules(action_delivery=rule))
    engine.reset(0, 0.0, None, seed=seed)
    for t in range(1, steps + 1):
        engine.apply(t)
        engine.observe(t, 0.0)
    return engine.stats()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--k", default="1,2,4,8,16,24,32")
    args = p.parse_args()
    print("| delay | mean age, newest | mean age, in order | never acted, newest | never acted, in order |")
    print("|---|---|---|---|---|")
    for k in (int(v) for v in args.k.split(",")):
        newest = measure(k, "newest", args.steps, args.seed)
        in_order = measure(k, "in_order", args.steps, args.seed)
        print(
            f"| Uniform(0, {k}) | {newest['mean_action_age_ticks']:.2f} | {in_order['mean_action_age_ticks']:.2f} "
            f"| {newest['never_acted_fraction']:.3f} | {in_order['never_acted_fraction']:.3f} |"
        )


if __name__ == "__main__":
    main()
