"""Frames per second streamed from frame publishers into a torch ``DataLoader``.

Agent side; it launches publisher sims. ``--publishers`` publishers of the
shipped CartPole (``launch_publishers("cartpole", P, width=S, height=S)``)
read by a ``DataLoader`` of ``--workers`` workers, at each render quality:
``cheap`` (the default since issue 36: no multisampling, no shadows) and
``quality`` (``quality=True``: the MJCF's own, MuJoCo's 4x MSAA and 4096²
shadow map, what every streamed frame used before). Each round reads
``--frames`` frames from each setting in turn (publishers started fresh and
warmed up by one batch, not counted), so load that comes and goes hits both
alike; the medians of ``--rounds`` rounds are printed with their ratio.
``--json PATH`` also writes the results. It measures and prints; it asserts
nothing::

    python -m remoteenv.benchmarks.streaming --size 64 --publishers 2 --workers 2
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from typing import Any

from remoteenv.benchmarks.harness.report import machine_record

#: name -> launch_publishers(quality=...)
SETTINGS = {"cheap": False, "quality": True}


def frames_per_second(size: int, publishers: int, workers: int, frames: int, batch: int, quality: bool) -> float:
    """Frames per second read through a DataLoader from fresh publishers, after one warm-up batch."""
    from torch.utils.data import DataLoader

    from remoteenv.integrations.frame_dataset import RemoteIterableDataset, launch_publishers

    per_publisher = -(-frames // publishers)
    with launch_publishers(
        "cartpole", publishers, width=size, height=size, seed=0, quality=quality, items_per_instance=None
    ) as pubs:
        dataset = RemoteIterableDataset.from_publishers(pubs, timeout=120.0)
        loader = DataLoader(dataset, batch_size=batch, num_workers=workers)
        it = iter(loader)
        next(it)  # warm-up: workers started, renderers made
        read, start = 0, time.perf_counter()
        while read < per_publisher * publishers:
            read += len(next(it)["index"])
        elapsed = time.perf_counter() - start
        del it
    return read / elapsed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64, help="frame width and height in pixels (default 64)")
    p.add_argument("--publishers", type=int, default=2)
    p.add_argument("--workers", type=int, default=2, help="DataLoader workers")
    p.add_argument("--batch", type=int, default=16, help="DataLoader batch size")
    p.add_argument("--frames", type=int, default=600, help="frames per setting per round (default 600)")
    p.add_argument("--quality-frames", type=int, default=120, help="frames per round at MJCF quality (slow)")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--json", default=None, help="also write the results to this file")
    args = p.parse_args(argv)
    with open("/proc/loadavg") as f:
        load_before = f.read().split()[0]
    runs: dict[str, list[float]] = {name: [] for name in SETTINGS}
    for r in range(args.rounds):
        for name, quality in SETTINGS.items():
            frames = args.quality_frames if quality else args.frames
            fps = frames_per_second(args.size, args.publishers, args.workers, frames, args.batch, quality)
            runs[name].append(fps)
            print(f"round {r + 1}: {name:8s} {fps:8.1f} frames/s", flush=True)
    medians = {name: statistics.median(values) for name, values in runs.items()}
    ratio = medians["cheap"] / medians["quality"]
    with open("/proc/loadavg") as f:
        load_after = f.read().split()[0]
    print(
        f"\n{args.size}x{args.size}, {args.publishers} publishers, {args.workers} DataLoader workers, "
        f"medians of {args.rounds} rounds (load average {load_before} before, {load_after} after):"
    )
    for name, value in medians.items():
        print(f"  {name:8s} {value:8.1f} frames/s")
    print(f"  cheap / quality: {ratio:.1f}x")
    if args.json:
        result: dict[str, Any] = {
            "benchmark": "streaming",
            "args": vars(args),
            "runs": runs,
            "medians": medians,
            "cheap_over_quality": ratio,
            "load_average": [load_before, load_after],
            "machine": machine_record(),
        }
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
            f.write("\n")
        print(f"wrote {os.path.abspath(args.json)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
