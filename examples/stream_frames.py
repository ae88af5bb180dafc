"""Stream rendered CartPole frames from sim processes into a torch DataLoader.

Two publisher sim processes each render their own world offscreen (random
actions, MUJOCO_GL=egl) and send frames with labels; a DataLoader with two
workers reads them, one publisher per worker, and this script saves a grid of
the frames with each frame's pole angle (a label) as its title.

    python examples/stream_frames.py --out frames.png

Needs torch and matplotlib (``pip install torch==2.13.0 matplotlib``).
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from torch.utils.data import DataLoader

from remoteenv.integrations.frame_dataset import RemoteIterableDataset, launch_publishers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="frames.png", help="PNG file to write")
    parser.add_argument("--instances", type=int, default=2, help="publisher sim processes")
    parser.add_argument("--workers", type=int, default=2, help="DataLoader worker processes")
    parser.add_argument("--items", type=int, default=16, help="frames per publisher (one pass)")
    parser.add_argument("--width", type=int, default=240)
    parser.add_argument("--height", type=int, default=160)
    args = parser.parse_args()

    start = time.perf_counter()
    with launch_publishers(
        "cartpole",
        num_instances=args.instances,
        items_per_instance=args.items,
        seed=0,
        episode_steps=40,
        width=args.width,
        height=args.height,
    ) as pubs:
        launched = time.perf_counter()
        loader = DataLoader(RemoteIterableDataset.from_publishers(pubs), batch_size=8, num_workers=args.workers)
        frames, titles, keys = [], [], []
        for batch in loader:
            for frame, instance, index, obs in zip(
                batch["frame"], batch["instance"], batch["index"], batch["labels"]["obs"]
            ):
                frames.append(frame.numpy())
                keys.append((int(instance), int(index)))
                titles.append(f"sim {int(instance)} #{int(index)}\ntheta {math.degrees(float(obs[2])):+.1f} deg")
        elapsed = time.perf_counter() - launched
    print(
        f"{len(frames)} frames of {args.height}x{args.width} from {args.instances} publishers "
        f"via {args.workers} workers: launch {launched - start:.2f} s, "
        f"streaming {elapsed:.2f} s ({len(frames) / elapsed:.0f} frames/s)"
    )

    order = sorted(range(len(frames)), key=lambda k: keys[k])  # workers interleave batches
    cols = 8
    rows = math.ceil(len(frames) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 2.0, rows * 1.7), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, k in zip(axes.flat, order):
        ax.imshow(frames[k])
        ax.set_title(titles[k], fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
