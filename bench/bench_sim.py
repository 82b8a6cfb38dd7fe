"""Simulator benchmark (SPEC §8): RGB-D frame time, real-time factor alone, ground-truth build.

Run: .venv/bin/python bench/bench_sim.py [--ticks 300] [--skip-gt] [--sensor-model-only]
Prints a markdown table of medians. Frames use the default (realistic) sensors; the sensor
model's own cost (invalid-return mask, then mask + noise) is timed on rendered frames. The
real-time factor is the simulator alone: physics plus rendering every robot's camera at the
default camera rate, no bus. The ground-truth time is the evaluator's build from scratch
(empty cache directory) and the later cached load.
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import services.simulator  # noqa: E402, F401  (picks the GL backend before MuJoCo loads)
from services.evaluator.world_truth import world_ground_truth  # noqa: E402
from services.simulator.config import SimConfig  # noqa: E402
from services.simulator.core import Simulation  # noqa: E402
from services.simulator.sensor_model import (  # noqa: E402
    PRESETS,
    apply_depth_model,
    invalid_return_mask,
)

AWS_HOUSE = Path(__file__).resolve().parents[2] / "shared/worlds/aws_small_house/small_house.xml"


def worlds() -> dict[str, str]:
    """Label → world name or path; the AWS house only when ../shared holds it."""
    out = {"house": "house", "bookstore": "bookstore", "warehouse": "warehouse"}
    if AWS_HOUSE.is_file():
        out["AWS house"] = str(AWS_HOUSE)
    return out


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


def sensor_model_ms(world: str, width: int, height: int) -> tuple[float, float]:
    """(invalid-return mask, whole realistic depth model) ms per frame, over 30 views."""
    sim = Simulation(SimConfig(world=world, robots=3, width=width, height=height,
                               sensors="ideal", render_backend="gl"))
    rng, model = np.random.default_rng(0), PRESETS["realistic"]
    mask_s, model_s = [], []
    for k in range(30):
        sim.step({0: (0.2, 0.3), 1: (0.3, -0.2), 2: (0.1, 0.5)})
        depth = sim.render(k % 3).depth_m
        for _ in range(10):
            t0 = time.perf_counter()
            invalid_return_mask(depth, sim.K, model.max_incidence_deg, model.edge_rel_jump)
            t1 = time.perf_counter()
            apply_depth_model(depth, sim.K, model, sim.cfg.range_m, rng)
            mask_s.append(t1 - t0)
            model_s.append(time.perf_counter() - t1)
    sim.close()
    return 1e3 * statistics.median(mask_s), 1e3 * statistics.median(model_s)


def frame_stages_ms(world: str) -> dict[str, float]:
    """Median ms per stage of one 160×120 GL frame (the camera's `_render_gl` split up, then
    the depth model): which part of a frame a faster simulator would have to cut."""
    import mujoco  # after services.simulator chose the GL backend

    sim = Simulation(SimConfig(world=world, robots=3, render_backend="gl"))
    sim.render(0)
    cam, rng = sim.camera, np.random.default_rng(0)
    stages: dict[str, list[float]] = {k: [] for k in (
        "mjv_updateScene", "mjr_render", "mjr_readPixels", "flip + depth", "depth model")}
    for k in range(60):
        sim.step({0: (0.2, 0.3)})
        cam._gl.make_current()
        cam._cam.fixedcamid = sim.robots[k % 3].camera
        t = [time.perf_counter()]
        mujoco.mjv_updateScene(cam.model, sim.data, cam._opt, None, cam._cam,
                               mujoco.mjtCatBit.mjCAT_ALL.value, cam._scene)
        t.append(time.perf_counter())
        mujoco.mjr_render(cam._rect, cam._scene, cam._ctx)
        t.append(time.perf_counter())
        mujoco.mjr_readPixels(cam._rgb, cam._zbuf, cam._rect, cam._ctx)  # waits for the GL
        t.append(time.perf_counter())
        np.flipud(cam._rgb).copy()
        depth = cam._d / (np.flipud(cam._zbuf) + cam._c)
        t.append(time.perf_counter())
        apply_depth_model(depth, cam.K, cam.sensors, cam.range_m, rng)
        t.append(time.perf_counter())
        for name, a, b in zip(stages, t[:-1], t[1:], strict=True):
            stages[name].append(b - a)
    sim.close()
    return {name: 1e3 * statistics.median(v) for name, v in stages.items()}


def realtime_factor(world: str, robots: int, ticks: int) -> tuple[float, float, float]:
    """(real-time factor, ms per tick rendering, ms per tick stepping) at the default rates."""
    cfg = SimConfig(world=world, robots=robots)
    sim = Simulation(cfg)
    rng = np.random.default_rng(0)
    sim.render(0)  # GL context set-up is not part of the run
    render_s = step_s = 0.0
    for k in range(ticks):
        t0 = time.perf_counter()
        if k % cfg.camera_every_ticks == 0:
            for i in range(robots):
                sim.render(i)
        t1 = time.perf_counter()
        sim.step({i: (rng.uniform(0, 0.5), rng.uniform(-0.7, 0.7)) for i in range(robots)})
        render_s += t1 - t0
        step_s += time.perf_counter() - t1
    sim.close()
    wall = render_s + step_s
    return ticks * cfg.tick_s / wall, 1e3 * render_s / ticks, 1e3 * step_s / ticks


def ground_truth_s(world: str) -> tuple[float, float]:
    """(build from scratch, cached load) seconds of the evaluator's ground truth of `world`."""
    cfg = SimConfig(world=world, robots=3)
    with tempfile.TemporaryDirectory() as cache:
        t0 = time.perf_counter()
        world_ground_truth(cfg, Path(cache))
        t1 = time.perf_counter()
        world_ground_truth(cfg, Path(cache))
        return t1 - t0, time.perf_counter() - t1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--ticks", type=int, default=300)
    parser.add_argument("--skip-gt", action="store_true", help="no ground-truth build times")
    parser.add_argument("--sensor-model-only", action="store_true",
                        help="only the depth model's cost per frame")
    parser.add_argument("--frame-stages", action="store_true",
                        help="only a 160×120 GL frame's stages (scene, render, read, depth)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    named = worlds()
    frame_worlds = [w for w in ("house", "AWS house") if w in named]
    lines = ["| measure | world | value |", "|---|---|---|"]
    if args.frame_stages:
        for label in frame_worlds:
            for name, ms in frame_stages_ms(named[label]).items():
                lines.append(f"| 160×120 frame: {name} | {label} | {ms:.2f} ms |")
        print("\n".join(lines))
        return
    for label in frame_worlds:
        for w, h in ((160, 120), (320, 240)):
            mask_ms, model_ms = sensor_model_ms(named[label], w, h)
            lines.append(f"| invalid-return mask {w}×{h} | {label} | {mask_ms:.2f} ms |")
            lines.append(f"| depth model (mask + noise) {w}×{h} | {label} | {model_ms:.2f} ms |")
    if args.sensor_model_only:
        print("\n".join(lines))
        return
    for label in frame_worlds:
        for backend in ("gl", "raycast"):
            for w, h in ((160, 120), (320, 240)):
                ms = frame_ms(named[label], w, h, backend, segmentation=False)
                lines.append(f"| RGB-D frame {w}×{h}, {backend} | {label} | {ms:.2f} ms |")
        for w, h in ((160, 120), (320, 240)):
            ms = frame_ms(named[label], w, h, "gl", segmentation=True)
            lines.append(f"| RGB-D + segmentation {w}×{h}, gl | {label} | {ms:.2f} ms |")
    runs = [(label, n) for label in frame_worlds for n in (3, 6)] + [("warehouse", 24)]
    for label, robots in runs:
        rtf, render_ms, step_ms = realtime_factor(named[label], robots, args.ticks)
        lines.append(
            f"| real-time factor, {robots} robots (render {render_ms:.1f} + step {step_ms:.1f}"
            f" ms/tick) | {label} | {rtf:.1f}× |"
        )
    if not args.skip_gt:
        for label, world in named.items():
            build, cached = ground_truth_s(world)
            lines.append(f"| ground truth build / cached load | {label} | "
                         f"{build:.1f} s / {1e3 * cached:.0f} ms |")
    print("Simulator benchmark (medians; RGB-D 160×120 every 2nd tick in the real-time factor)\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
