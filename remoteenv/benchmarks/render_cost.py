"""Milliseconds per camera frame at each offscreen render quality.

Runs in this process (no sim): the shipped CartPole's ``agent`` camera
rendered with ``mujoco.Renderer`` (``update_scene`` + ``render``) at four
settings of ``model.vis.quality`` made before the renderer:

- ``default``: MuJoCo's defaults as the MJCF leaves them (4x MSAA, 4096² shadow map);
- ``cheap``: ``offsamples=0``, ``shadowsize=0`` (what a camera observation uses
  unless the scene asks for quality);
- ``msaa only``: 4x MSAA, no shadow map;
- ``shadows only``: no MSAA, the 4096² shadow map.

The settings take turns in rounds (so a change of load hits them all), and
each figure is the median of its rounds. Run it as
``python -m remoteenv.benchmarks.render_cost [--size 64] [--rounds 5]``;
it prints and asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import mujoco

from remoteenv import scene_path

#: name -> (offsamples, shadowsize); None: as the model says.
SETTINGS: dict[str, tuple[int, int] | None] = {
    "default": None,
    "cheap": (0, 0),
    "msaa only": (4, 0),
    "shadows only": (0, 4096),
}


def _model_path() -> str:
    return os.path.join(os.path.dirname(scene_path("cartpole")), "cartpole.xml")


def render_cost(size: int = 64, rounds: int = 5, frames: int = 10, camera: str = "agent") -> dict[str, float]:
    """Median milliseconds per ``size`` x ``size`` frame at each of :data:`SETTINGS`."""
    renderers: dict[str, tuple[mujoco.Renderer, mujoco.MjData]] = {}
    for name, setting in SETTINGS.items():
        model = mujoco.MjModel.from_xml_path(_model_path())
        if setting is not None:
            model.vis.quality.offsamples, model.vis.quality.shadowsize = setting
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        renderers[name] = (mujoco.Renderer(model, height=size, width=size), data)
    times: dict[str, list[float]] = {name: [] for name in SETTINGS}
    try:
        for renderer, data in renderers.values():  # warm up: first frames compile shaders
            renderer.update_scene(data, camera=camera)
            renderer.render()
        for _ in range(rounds):
            for name, (renderer, data) in renderers.items():
                start = time.perf_counter()
                for _ in range(frames):
                    renderer.update_scene(data, camera=camera)
                    renderer.render()
                times[name].append((time.perf_counter() - start) / frames * 1e3)
    finally:
        for renderer, _ in renderers.values():
            renderer.close()
    return {name: statistics.median(values) for name, values in times.items()}


def format_cost(costs: dict[str, float], size: int) -> str:
    cheap = costs["cheap"]
    lines = [f"ms per {size}x{size} frame (CartPole's agent camera, mujoco.Renderer):"]
    for name, ms in costs.items():
        lines.append(f"  {name:13s} {ms:8.2f} ms  ({ms / cheap:6.1f}x cheap)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=64, help="image side in pixels (default 64)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds over the settings (default 5)")
    parser.add_argument("--frames", type=int, default=10, help="frames per setting per round (default 10)")
    args = parser.parse_args(argv)
    print(format_cost(render_cost(args.size, args.rounds, args.frames), args.size))
    print(f"load average at end: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
