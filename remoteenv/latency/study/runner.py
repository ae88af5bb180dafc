"""Run every cell of a delay-effect study, in parallel worker processes, with
a progress bar, writing ``delay_effect.json`` after every finished cell
(agent side; needs Stable-Baselines3, torch and tqdm).

Each worker is a fresh (spawned) Python process that trains one cell at a
time with one torch thread; each cell starts its own sim process. Use one
worker per CPU core: PPO's updates and the sims then share the cores evenly.
The progress bar counts training steps over all cells; workers report theirs
through a queue every :data:`~remoteenv.latency.study.training.CURVE_EVERY` steps.
"""

from __future__ import annotations

import multiprocessing
import os
import platform
import queue
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from remoteenv.latency.study.design import Cell, StudyConfig, cells
from remoteenv.latency.study.results import MAX_STUDY_FILE, load_records, record_key, write_json
from remoteenv.wire.files.file_reads import read_json


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
    """The study file as the resumed run found it (read bounded; {} when unreadable)."""
    try:
        data = read_json(json_path, MAX_STUDY_FILE, what="study file")
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


def _run_cell(config: StudyConfig, cell: Cell, policy_dir: str | None, steps: Any = None) -> dict[str, Any]:
    """Run one cell in a worker; ``steps`` (a queue) gets ``(cell key, steps done)``."""
    from remoteenv.latency.study.training import run_cell

    progress = None if steps is None else (lambda done: steps.put((cell.key, int(done))))
    return run_cell(config, cell, policy_dir, progress)


class _StepBar:
    """A tqdm bar of training steps over the cells, each counted up to ``steps``."""

    def __init__(self, cells: int, steps: int) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=cells * steps, unit="step", unit_scale=True, desc="delay study")
        self.steps = steps
        self._done: dict[Any, int] = {}

    def advance(self, key: Any, done: int) -> None:
        done = min(done, self.steps)
        before = self._done.get(key, 0)
        if done > before:
            self._done[key] = done
            self.bar.update(done - before)


class _Direct:
    """The queue's ``put`` for cells run in this process: straight to the bar."""

    def __init__(self, bar: _StepBar, key: Any) -> None:
        self._bar, self._key = bar, key

    def put(self, report: tuple[Any, int]) -> None:
        self._bar.advance(self._key, report[1])


def _drain(reports: Any, bar: _StepBar) -> None:
    """Count every step report the workers queued so far."""
    while True:
        try:
            key, done = reports.get_nowait()
        except queue.Empty:
            return
        bar.advance(tuple(key), int(done))


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

    steps = _StepBar(len(todo), config.steps)
    with steps.bar as bar:
        if workers <= 1:
            for cell in todo:
                bar.set_postfix_str(cell.label())
                finished(_run_cell(config, cell, policy_dir, _Direct(steps, cell.key)))
                steps.advance(cell.key, config.steps)
        else:
            context = multiprocessing.get_context("spawn")
            with context.Manager() as manager, ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
                reports = manager.Queue()
                try:
                    futures = {pool.submit(_run_cell, config, cell, policy_dir, reports): cell for cell in todo}
                    pending = set(futures)
                    while pending:
                        ready, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                        _drain(reports, steps)
                        for future in ready:
                            record = future.result()
                            cell = futures[future]
                            finished(record)
                            steps.advance(cell.key, config.steps)
                            bar.set_postfix_str(f"{cell.label()}: {record['mean_return']:.0f}")
                except BaseException:  # Ctrl-C, SIGTERM, a failed cell: the running cells stop too
                    _stop_workers(pool)
                    raise
    data["wall_s"] = earlier_s + time.perf_counter() - started
    data["segments"] = segments + [time.perf_counter() - started]
    data["host"]["load_average_end"] = list(os.getloadavg())
    write_json(json_path, data)
    return data
