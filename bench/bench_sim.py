"""Simulator benchmark: RGB-D frame time and real-time factor (SPEC §8).

Run: .venv/bin/python bench/bench_sim.py [--world house] [--ticks 300]
Prints a markdown table of medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from services.simulator.config import SimConfig  # noqa: E402
from services.simulator.core import Simulation  # noqa: E402


def frame_ms(world: str, width: int, height: int, backend: str, segmentation: bool) -> float:
    sim = Simulation(SimConfig(world=world, robots=3, width=width, height=height,
                               render_backend=backend))
    for _ in range(5):
        sim.render(0, segmentation)
    times = []
    for k in range(60):
        sim.step({0: (0.2, 0.3)})
        t0 = time.perf_counter()
        sim.render(k % 3, segmentation)
        times.append(time.perf_counter() - t0)
    sim.close()
    return 1e3 * statistics.median(times)


def realtime_factor(world: str, robots: int, ticks: int, render: bool) -> float:
    cfg = SimConfig(world=world, robots=robots)
    sim = Simulation(cfg)
    rng = np.random.default_rng(0)
    sim.render(0)  # GL context set-up is not part of the run
    t0 = time.perf_counter()
    for k in range(ticks):
        if render and k % cfg.camera_every_ticks == 0:
            for i in range(robots):
                sim.render(i)
        sim.step({i: (rng.uniform(0, 0.5), rng.uniform(-0.7, 0.7)) for i in range(robots)})
    wall = time.perf_counter() - t0
    sim.close()
    return ticks * cfg.tick_s / wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--world", default="house")
    parser.add_argument("--ticks", type=int, default=300)
    args = parser.parse_args()
    lines = ["| measure | value |", "|---|---|"]
    for backend in ("gl", "raycast"):
        for w, h in ((160, 120), (320, 240)):
            ms = frame_ms(args.world, w, h, backend, segmentation=False)
            lines.append(f"| RGB-D frame {w}×{h}, {backend} | {ms:.2f} ms |")
    for w, h in ((160, 120), (320, 240)):
        ms = frame_ms(args.world, w, h, "gl", segmentation=True)
        lines.append(f"| RGB-D + segmentation {w}×{h}, gl | {ms:.2f} ms |")
    for robots in (3, 6):
        for render in (False, True):
            rtf = realtime_factor(args.world, robots, args.ticks, render)
            what = "with RGB-D 160×120 every 2nd tick" if render else "physics only"
            lines.append(f"| real-time factor, {robots} robots, {what} | {rtf:.0f}× |")
    print(f"Simulator benchmark, world `{args.world}`, medians\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
