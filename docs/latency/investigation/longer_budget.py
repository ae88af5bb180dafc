"""The history + alpha variant of the latency study at a larger budget.

Trains the ``history`` cells of the given random models (three seeds each)
with the study's PPO settings and ``--steps`` steps instead of the study's
400,000, two at a time, and writes every record (the study's record format)
to ``--out`` after each finished cell::

    python docs/latency/investigation/longer_budget.py --models 4:8,6:10 --steps 1000000 \
        --out docs/latency/investigation/history_alpha_1M.json
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

from remoteenv.cli.latency_study import random_models
from remoteenv.latency.study.design import Cell, StudyConfig
from remoteenv.latency.study.results import write_json
from remoteenv.latency.study.runner import host_facts
from remoteenv.latency.study.training import run_cell


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", default="4:8,6:10")
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    models = random_models(args.models)
    seeds = tuple(int(s) for s in args.seeds.split(","))
    config = StudyConfig(delays=(), random_delays=tuple(models), seeds=seeds, steps=args.steps)
    todo = [Cell("history", "random", m, s) for m in models for s in seeds]
    data = {"config": config.to_json(), "cells": "history only", "wall_s": None, "host": host_facts(), "records": []}
    started = time.perf_counter()
    write_json(args.out, data)
    with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(run_cell, config, cell): cell for cell in todo}
        for future in as_completed(futures):
            record = future.result()
            data["records"].append(record)
            data["wall_s"] = time.perf_counter() - started
            write_json(args.out, data)
            print(f"{futures[future].label()}: {record['mean_return']:.0f} {record['returns']}", flush=True)


if __name__ == "__main__":
    main()
