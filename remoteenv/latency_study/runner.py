"""Run every cell of a delay-effect study, in parallel worker processes, with
a progress bar, writing ``delay_effect.json`` after every finished cell
(agent side; needs Stable-Baselines3, torch and tqdm).

Each worker is a fresh (spawned) Python process that trains one cell at a
time with one torch thread; each cell starts its own sim process. Use one
worker per CPU core: PPO's updates and the sims then share the cores evenly.
"""

from __future__ import annotations

import multiprocessing
import os
import platform
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from remoteenv.latency_study.design import Cell, StudyConfig, cells
from remoteenv.latency_study.results import load_records, record_key, write_json


def host_facts() -> dict[str, Any]:
    """What a reader needs to compare wall times: CPUs, load, versions."""
    import mujoco
    import stable_baselines3
    import torch

    return {
        "cpus": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
    }


def _earlier(json_path: str) -> dict[str, Any]:
    import json

    try:
        with open(json_path) as f:
            data = json.load(f)
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _earlier_segments(json_path: str) -> list[float]:
    """The training wall times (s) of the earlier finished segments of a resumed
    study (one cut off before its end wrote no wall time and is not counted)."""
    data = _earlier(json_path)
    segments = data.get("segments")
    if isinstance(segments, list) and all(isinstance(s, (int, float)) for s in segments) and data.get("wall_s"):
        return [float(s) for s in segments]
    if isinstance(data.get("wall_s"), (int, float)):
        return [float(data["wall_s"])]
    return []


def _earlier_wall_s(json_path: str) -> float:
    return float(sum(_earlier_segments(json_path)))


def _run_cell(config: StudyConfig, cell: Cell, policy_dir: str | None) -> dict[str, Any]:
    from remoteenv.latency_study.training import run_cell

    return run_cell(config, cell, policy_dir)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """End ``pool``'s worker processes now (SIGTERM; each one's sims and dirs
    follow it out) and drop the cells not started."""
    terminate = getattr(pool, "terminate_workers", None)  # Python 3.14+
    if terminate is not None:
        terminate()
        return
    processes = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown drops them
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()


def run_study(
    config: StudyConfig,
    json_path: str,
    workers: int = 2,
    resume: bool = False,
    policy_dir: str | None = None,
    on_record: Callable[[dict[str, Any]], None] | None = None,
    references: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train and evaluate every cell of ``config`` not yet in ``json_path``
    (with ``resume``; otherwise all of them) and return the study's data.

    Args:
        config: the study.
        json_path: where ``delay_effect.json`` is written after each cell.
        workers: worker processes (1 runs the cells in this process).
        resume: keep the records of an earlier run of the same configuration;
            ``wall_s`` then adds this run's training wall time to the earlier
            segments' (``segments``: each segment's; a segment interrupted
            before its end is not counted).
        policy_dir: if given, each trained policy is saved there (SB3 zip).
        on_record: called in this process with each finished record.
        references: the reference controllers' returns, stored as they are.
    """
    from tqdm import tqdm

    records = load_records(json_path, config) if resume else []
    earlier_s = _earlier_wall_s(json_path) if resume and records else 0.0
    done = {record_key(r) for r in records}
    todo = [c for c in cells(config) if c.key not in done]
    segments = _earlier_segments(json_path) if resume and records else []
    started = time.perf_counter()
    data: dict[str, Any] = {
        "config": config.to_json(),
        "wall_s": None,
        "host": host_facts(),
        "references": references,
        "records": records,
    }
    write_json(json_path, data)

    def finished(record: dict[str, Any]) -> None:
        records.append(record)
        write_json(json_path, data)
        if on_record is not None:
            on_record(record)

    with tqdm(total=len(todo), unit="run", desc="delay study") as bar:
        if workers <= 1:
            for cell in todo:
                bar.set_postfix_str(cell.label())
                finished(_run_cell(config, cell, policy_dir))
                bar.update(1)
        else:
            context = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
                try:
                    futures = {pool.submit(_run_cell, config, cell, policy_dir): cell for cell in todo}
                    for future in as_completed(futures):
                        record = future.result()
                        finished(record)
                        bar.set_postfix_str(f"{futures[future].label()}: {record['mean_return']:.0f}")
                        bar.update(1)
                except BaseException:  # Ctrl-C, SIGTERM, a failed cell: the running cells stop too
                    _stop_workers(pool)
                    raise
    data["wall_s"] = earlier_s + time.perf_counter() - started
    data["segments"] = segments + [time.perf_counter() - started]
    data["host"]["load_average_end"] = list(os.getloadavg())
    write_json(json_path, data)
    return data
