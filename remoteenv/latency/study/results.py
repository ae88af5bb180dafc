"""The delay-effect study's results: its JSON file, a summary per delay, a
Markdown table and the figure (agent side; the figure needs matplotlib).

``delay_effect.json`` is one map::

    {"config": {...StudyConfig...}, "wall_s": float or null, "host": {...},
     "references": {"constant": {name: {delay: return}}, "random": {...},
                    "gains": {name: [4 gains]}} or null,
     "records": [{"variant", "kind", "delay", "seed", "mean_return",
                  "returns", "history_length", "include_alpha", "steps",
                  "mean_age_ticks", "dropped_fraction",
                  "train_s", "train_return", "curve"}, ...]}

``delay`` names the delay model: the int ``k`` (``kind="constant"``) or a
name like ``"U(6,10)"`` (``kind="random"``). ``mean_return`` is the mean of
``returns``: the deterministic policy's episode returns at the delay it was
trained under; ``mean_age_ticks`` and ``dropped_fraction`` are what the
delays did during those episodes (``env.unwrapped.latency_stats``: the mean
age of the action in force, and the fraction of actions that never acted;
null without delay). The file is rewritten
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

from remoteenv.latency.study.design import KINDS, VARIANTS, StudyConfig
from remoteenv.latency.study.resumed import BadRecord, check_records
from remoteenv.wire.files.file_reads import read_json

RecordKey = tuple[str, str, int | str, int]


def record_key(record: dict[str, Any]) -> RecordKey:
    delay = record["delay"]
    return (
        str(record["variant"]),
        str(record["kind"]),
        delay if isinstance(delay, str) else int(delay),
        int(record["seed"]),
    )


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
    against ``config`` (:func:`remoteenv.latency.study.resumed.check_records`).

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


def _mean_of(values: list[Any]) -> float | None:
    real = [float(v) for v in values if v is not None]
    return float(np.mean(real)) if real else None


def summarize(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (kind, delay, variant), in the order the records first name them
    within each kind (constant delays by size): the seeds' mean returns,
    their mean, std, min and max, and the delays' measured mean age and
    dropped fraction (means over the seeds; None if not measured)."""
    groups: dict[tuple[str, int | str, str], list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault((r["kind"], r["delay"], r["variant"]), []).append(r)
    order = {k: i for i, k in enumerate(KINDS)}
    vorder = {v: i for i, v in enumerate(VARIANTS)}
    first = {key[:2]: i for i, key in reversed(list(enumerate(groups)))}

    def sort_key(key: tuple[str, int | str, str]) -> tuple[int, float, int]:
        kind, delay, variant = key
        position = float(delay) if kind == "constant" else float(first[key[:2]])
        return (order.get(kind, len(order)), position, vorder.get(variant, len(vorder)))

    out = []
    for key in sorted(groups, key=sort_key):
        kind, delay, variant = key
        group = groups[key]
        values = [float(r["mean_return"]) for r in group]
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
                "mean_age_ticks": _mean_of([r.get("mean_age_ticks") for r in group]),
                "dropped_fraction": _mean_of([r.get("dropped_fraction") for r in group]),
            }
        )
    return out


def delay_label(kind: str, delay: int | str) -> str:
    """How a table names a delay model: ``8`` or ``U(6,10)``."""
    return str(delay)


def _reference_names(references: dict[str, Any] | None) -> list[str]:
    names: list[str] = []
    for kind in KINDS:
        names += [n for n in (references or {}).get(kind, {}) if n not in names]
    return names


def _format(value: float | None, spec: str) -> str:
    return "–" if value is None else format(value, spec)


def markdown_table(records: Iterable[dict[str, Any]], references: dict[str, Any] | None = None) -> str:
    """Rows: delay model; columns: the measured mean age of the action in
    force and the fraction of actions that never acted (means over the
    row's runs), each variant's mean over seeds (min–max) and the per-seed
    returns, then each reference controller's return (– where it was not run)."""
    summary = summarize(records)
    rows: dict[tuple[str, int | str], dict[str, dict[str, Any]]] = {}
    for s in summary:
        rows.setdefault((s["kind"], s["delay"]), {})[s["variant"]] = s
    names = _reference_names(references)
    head = (
        "| action delay (ticks) | mean age of the action in force (ticks) | actions never acted |"
        " plain: mean (min–max) | plain: per seed | history: mean (min–max) | history: per seed |"
    )
    lines = [head + "".join(f" {name} |" for name in names), "|---|---|---|---|---|---|---|" + "---|" * len(names)]
    for (kind, delay), by_variant in rows.items():
        groups = list(by_variant.values())
        age = _mean_of([g["mean_age_ticks"] for g in groups])
        dropped = _mean_of([g["dropped_fraction"] for g in groups])
        cells = [delay_label(kind, delay), _format(age, ".2f"), _format(dropped, ".2f")]
        for variant in VARIANTS:
            group = by_variant.get(variant)
            if group is None:
                cells += ["–", "–"]
                continue
            cells.append(f"{group['mean']:.0f} ({group['min']:.0f}–{group['max']:.0f})")
            cells.append(", ".join(f"{v:.0f}" for v in group["seed_means"]))
        for name in names:
            value = (references or {}).get(kind, {}).get(name, {}).get(str(delay))
            cells.append(_format(value, ".0f"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(records: list[dict[str, Any]], path: str, title: str, references: dict[str, Any] | None = None) -> None:
    """One panel per kind of delay model: each seed's mean return as a point,
    the mean over seeds with ± one standard deviation, per variant; and the
    reference controllers' returns (``{kind: {name: {delay: return}}}``, see
    :mod:`remoteenv.latency.study.references`) as grey lines. Constant delays
    on a tick axis; random models side by side, in the study's order."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = [k for k in KINDS if any(r["kind"] == k for r in records)]
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.6 * len(kinds), 4.8), squeeze=False, sharey=True)
    colors = {"plain": "tab:red", "history": "tab:blue"}
    labels = {
        "constant": {"plain": "plain (observation only)", "history": "history (+ actions in flight)"},
        "random": {"plain": "plain (observation only)", "history": "history (+ action buffer + alpha)"},
    }
    summary = summarize(records)
    for ax, kind in zip(axes[0], kinds):
        models = list(dict.fromkeys(s["delay"] for s in summary if s["kind"] == kind))
        where = {m: (float(m) if kind == "constant" else float(i)) for i, m in enumerate(models)}
        width = 1.0 if kind == "constant" else 0.25
        for i, variant in enumerate(VARIANTS):
            points = [s for s in summary if s["kind"] == kind and s["variant"] == variant]
            if not points:
                continue
            x = np.array([where[s["delay"]] for s in points]) + (i - 0.5) * 0.35 * width
            for xi, s in zip(x, points):
                ax.scatter([xi] * len(s["seed_means"]), s["seed_means"], s=14, color=colors[variant], alpha=0.45)
            ax.errorbar(
                x,
                [s["mean"] for s in points],
                yerr=[s["std"] for s in points],
                color=colors[variant],
                marker="o",
                capsize=3,
                linestyle="-" if kind == "constant" else "none",
                label=labels[kind][variant],
            )
        for (name, by_delay), style in zip((references or {}).get(kind, {}).items(), (":", "--", "-.")):
            ds = [m for m in models if str(m) in by_delay]
            ax.plot(
                [where[m] for m in ds],
                [by_delay[str(m)] for m in ds],
                linestyle=style if kind == "constant" else "none",
                marker="_" if kind == "random" else ".",
                markersize=18 if kind == "random" else 6,
                color="0.2" if "LQR" in name else "0.55",
                label=name,
            )
        ax.set_xticks([where[m] for m in models])
        if kind == "random":
            ax.set_xticklabels([str(m) for m in models])
        ax.set_ylim(bottom=0)
        ax.set_xlabel("action delay k (ticks)" if kind == "constant" else "action delay model (ticks, newest-due)")
        ax.set_title("constant delay" if kind == "constant" else "random delay", fontsize=10)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("evaluation return (per seed; mean ± std)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
