"""The training-loop benchmark's figure: each contender's steps per second, per N.

Runs in the agent process (benchmarks only; needs matplotlib, the ``torch``
extra). One panel per vector size N; one bar per contender, its height the
median over the rounds, its whisker the slowest to the fastest round; each
bar is labelled with its median and its ratio to EnvPool's (when EnvPool ran;
a dashed line marks EnvPool's median).
The caption says when and where the run took place, the CPU hogs beside it
and the load average after its rounds, as the table does.
"""

from __future__ import annotations

from typing import Any

#: The contender every bar is compared with, when it ran.
ANCHOR = "EnvPool"


def plot_train_loop(result: dict[str, Any], path: str) -> None:
    """Draw ``result`` (the benchmark's JSON record) into the image file ``path``
    (its format from the suffix, e.g. ``.png`` or ``.svg``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    sizes = sorted({int(r["num_envs"]) for r in rows})
    if not sizes:
        raise ValueError("the result has no rows to draw")
    fig, axes = plt.subplots(
        1, len(sizes), figsize=(6.8 * len(sizes), 0.55 * _most(rows, sizes) + 1.8), squeeze=False, layout="constrained"
    )
    for ax, n in zip(axes[0], sizes):
        mine = [r for r in rows if int(r["num_envs"]) == n]
        anchor = next((r["median"] for r in mine if r["name"] == ANCHOR), None)
        names = [r["name"] for r in mine]
        medians = [float(r["median"]) for r in mine]
        lows = [m - min(r["rates"]) for m, r in zip(medians, mine)]
        highs = [max(r["rates"]) - m for m, r in zip(medians, mine)]
        colours = ["tab:orange" if name.startswith("remoteenv") else "tab:blue" for name in names]
        ax.barh(range(len(mine)), medians, xerr=[lows, highs], color=colours, capsize=3)
        ax.set_yticks(range(len(mine)), labels=names)
        ax.invert_yaxis()
        ax.set_xlabel("steps/s: median, whisker the slowest to the fastest round")
        ax.set_title(f"N = {n}")
        ends = [m + h for m, h in zip(medians, highs)]
        for i, m in enumerate(medians):
            label = f"{m:,.0f}" + (f" ({m / anchor:.2f}x)" if anchor else "")
            ax.text(ends[i] * 1.02, i, label, va="center", ha="left", fontsize=8)
        ax.set_xlim(0, max(ends) * 1.45)
        if anchor:
            ax.axvline(anchor, color="grey", linestyle="--", linewidth=1)
    loads = result.get("load_avg_per_round") or []
    load = f"load average {min(loads):.1f}-{max(loads):.1f} after rounds" if loads else "load not recorded"
    machine = result.get("machine", {})
    fig.suptitle(
        f"PPO-shaped training loop, {result.get('rounds')} rounds x {result.get('duration_s')} s per contender; "
        f"{result.get('date')}, {machine.get('cpus')} CPUs, CPU hogs: {result.get('hogs')}, {load}; "
        f"in brackets: the median over {ANCHOR}'s (dashed)",
        fontsize=9,
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _most(rows: list[dict[str, Any]], sizes: list[int]) -> int:
    return max(sum(1 for r in rows if int(r["num_envs"]) == n) for n in sizes)


__all__ = ["ANCHOR", "plot_train_loop"]
