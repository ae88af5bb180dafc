"""The delay-effect study's results: its JSON file, a summary per delay, a
Markdown table and the figure (agent side; the figure needs matplotlib).

``delay_effect.json`` is one map::

    {"config": {...StudyConfig...}, "wall_s": float or null, "host": {...},
     "records": [{"variant", "kind", "delay", "seed", "mean_return",
                  "returns", "history_length", "include_alpha", "steps",
                  "train_s", "train_return", "curve"}, ...]}

``mean_return`` is the mean of ``returns``: the deterministic policy's
episode returns at the delay it was trained under. The file is rewritten
after every finished cell (write to a temporary file, then rename), so an
interrupted study keeps what it finished and ``--resume`` continues it.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterable
from typing import Any

import numpy as np

from remoteenv.latency_study.design import KINDS, VARIANTS, StudyConfig
from remoteenv.latency_study.resumed import BadRecord, check_records
from remoteenv.wire.files.file_reads import read_json

RecordKey = tuple[str, str, int, int]


def record_key(record: dict[str, Any]) -> RecordKey:
    return (str(record["variant"]), str(record["kind"]), int(record["delay"]), int(record["seed"]))


def write_json(path: str, data: dict[str, Any]) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then
    rename), readable as any file the user creates (mode 0666 less the umask)."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".delay_effect.", suffix=".json", dir=folder)
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=1)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


#: Largest study file ``--resume`` reads (a full study's is well under 1 MiB).
MAX_STUDY_FILE = 64 << 20


def load_records(path: str, config: StudyConfig) -> list[dict[str, Any]]:
    """The records of an earlier run of the same configuration at ``path`` (none
    if nothing is there), read through the bounded reader (a regular file,
    opened without blocking, size and nesting bounded) and each checked
    against ``config`` (:func:`remoteenv.latency_study.resumed.check_records`).

    Raises ``ValueError`` naming ``path`` for another configuration, a file
    that is not a study file or a record this study could not have written,
    and ``OSError`` if it cannot be opened."""
    if not os.path.lexists(path):
        return []
    data = read_json(path, MAX_STUDY_FILE, what="study file")
    if not isinstance(data, dict) or data.get("config") != config.to_json():
        raise ValueError(f"{path} holds a study with another configuration; choose another --out or drop --resume")
    try:
        return list(check_records(data.get("records", []), config))
    except BadRecord as exc:
        raise ValueError(f"{path} is refused: {exc}; remove it or choose another --out") from None


def summarize(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (kind, delay, variant): the seeds' mean returns, their mean, std, min and max."""
    groups: dict[tuple[str, int, str], list[float]] = {}
    for r in records:
        groups.setdefault((r["kind"], int(r["delay"]), r["variant"]), []).append(float(r["mean_return"]))
    order = {k: i for i, k in enumerate(KINDS)}
    vorder = {v: i for i, v in enumerate(VARIANTS)}
    out = []
    for (kind, delay, variant), values in sorted(
        groups.items(), key=lambda g: (order[g[0][0]], g[0][1], vorder[g[0][2]])
    ):
        out.append(
            {
                "kind": kind,
                "delay": delay,
                "variant": variant,
                "seeds": len(values),
                "mean": float(np.mean(values)),
                "std": float(np.std(values)),
                "min": float(np.min(values)),
                "max": float(np.max(values)),
                "seed_means": values,
            }
        )
    return out


def delay_label(kind: str, delay: int) -> str:
    return f"Uniform(0, {delay})" if kind == "uniform" else f"{delay}"


def markdown_table(
    records: Iterable[dict[str, Any]], references: dict[str, dict[str, dict[str, float]]] | None = None
) -> str:
    """Rows: delay model; columns: each variant's mean over seeds (min–max) and
    the per-seed returns, then each reference controller's return (– where it
    was not run)."""
    summary = summarize(records)
    rows: dict[tuple[str, int], dict[str, dict[str, Any]]] = {}
    for s in summary:
        rows.setdefault((s["kind"], s["delay"]), {})[s["variant"]] = s
    names = list(dict.fromkeys(name for by_name in (references or {}).values() for name in by_name))
    head = "| action delay (ticks) | plain: mean (min–max) | plain: per seed | history: mean (min–max) | history: per seed |"
    lines = [head + "".join(f" {name} |" for name in names), "|---|---|---|---|---|" + "---|" * len(names)]
    for (kind, delay), by_variant in rows.items():
        cells = [delay_label(kind, delay)]
        for variant in VARIANTS:
            group = by_variant.get(variant)
            if group is None:
                cells += ["–", "–"]
                continue
            cells.append(f"{group['mean']:.0f} ({group['min']:.0f}–{group['max']:.0f})")
            cells.append(", ".join(f"{v:.0f}" for v in group["seed_means"]))
        for name in names:
            value = (references or {}).get(kind, {}).get(name, {}).get(str(delay))
            cells.append("–" if value is None else f"{value:.0f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(
    records: list[dict[str, Any]],
    path: str,
    title: str,
    references: dict[str, dict[str, dict[str, float]]] | None = None,
) -> None:
    """One panel per delay model: each seed's mean return as a point, the mean
    over seeds with ± one standard deviation, per variant; and the reference
    controllers' returns (``{kind: {name: {delay: return}}}``, see
    :mod:`remoteenv.latency_study.references`) as grey lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = [k for k in KINDS if any(r["kind"] == k for r in records)]
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.2 * len(kinds), 3.8), squeeze=False, sharey=True)
    colors = {"plain": "tab:red", "history": "tab:blue"}
    labels = {"plain": "plain (observation only)", "history": "history (+ actions in flight)"}
    summary = summarize(records)
    for ax, kind in zip(axes[0], kinds):
        for i, variant in enumerate(VARIANTS):
            points = [s for s in summary if s["kind"] == kind and s["variant"] == variant]
            if not points:
                continue
            offset = (i - 0.5) * 0.35
            x = np.array([s["delay"] for s in points], dtype=float) + offset
            for xi, s in zip(x, points):
                ax.scatter([xi] * len(s["seed_means"]), s["seed_means"], s=14, color=colors[variant], alpha=0.45)
            ax.errorbar(
                x,
                [s["mean"] for s in points],
                yerr=[s["std"] for s in points],
                color=colors[variant],
                marker="o",
                capsize=3,
                label=labels[variant] + (" + latency" if kind == "uniform" and variant == "history" else ""),
            )
        for (name, by_delay), style in zip((references or {}).get(kind, {}).items(), (":", "--", "-.")):
            ds = sorted(by_delay, key=int)
            ax.plot(
                [int(d) for d in ds], [by_delay[d] for d in ds], linestyle=style, marker=".", color="0.4", label=name
            )
        ax.set_xticks(sorted({int(r["delay"]) for r in records if r["kind"] == kind}))
        ax.set_ylim(bottom=0)
        ax.set_xlabel("action delay k (ticks)" if kind == "constant" else "action delay Uniform(0, k): k (ticks)")
        ax.set_title("constant delay" if kind == "constant" else "random delay", fontsize=10)
        ax.legend(fontsize=7, loc="best")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("evaluation return (per seed; mean ± std)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
