"""Benchmark the evaluator: ground truth of the AWS house and metrics on a 200k-point map.

Run: .venv/bin/python bench/bench_eval.py  (prints a markdown table; medians of --repeat runs)
     .venv/bin/python bench/bench_eval.py --run RUN_DIR  (the scoring a mission ends with: a
     finished run folder's metrics, as `spacemap run` computes them after the last tick)
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np

from services.evaluator import metrics as mx
from services.evaluator import run_files as rf
from services.evaluator.config import EvalConfig
from services.evaluator.evaluate import RunConfig, evaluate_run_folder, probe_for
from services.evaluator.free_space import reachable_free_grid
from services.evaluator.gazebo_map import compare_with_ros_map, load_ros_map
from services.evaluator.ground_truth import GroundTruth
from services.evaluator.observable import observable_surface
from services.evaluator.scoring import Probe, map_quality
from services.evaluator.surfaces import surface_samples

log = logging.getLogger("bench_eval")
AWS = Path(__file__).resolve().parents[1].parent / "shared" / "worlds" / "aws_small_house"
SPAWN = np.array([[2.9, 1.0], [3.5, 1.0], [4.1, 1.0]])


def timed(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--run", type=Path, default=None,
                        help="time the end-of-mission scoring of this finished run folder")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.run is not None:
        time_run_folder(args.run, args.repeat)
        return
    model = mujoco.MjModel.from_xml_path(str(AWS / "small_house.xml"))
    rows: list[tuple[str, float, str]] = []
    t, grid = timed(lambda: reachable_free_grid(model, SPAWN), args.repeat)
    rows.append(("free grid (0.05 m)", t, f"{grid.free_area_m2:.1f} m² reachable"))
    t, (points, tri, _) = timed(lambda: surface_samples(model), args.repeat)
    rows.append(("surface samples (1000/m²)", t, f"{len(points)} points"))
    t, seen = timed(lambda: observable_surface(model, points, grid, triangle_ids=tri), 1)
    rows.append(("observable filter", t, f"{seen.sum()} observable ({100 * seen.mean():.1f} %)"))
    cmp = compare_with_ros_map(grid, load_ros_map(AWS / "gazebo_map.yaml"))
    rows.append(("gazebo map check", 0.0, f"IoU {cmp['free_iou']:.3f}, "
                 f"agreement {cmp['agreement_pct']:.1f} %"))
    gt = points[seen]
    rng = np.random.default_rng(0)
    map_pts = gt[rng.choice(len(gt), 200_000)] + rng.normal(0, 0.01, (200_000, 3))
    for name, fn in [
        ("coverage_3d (200k map)", lambda: mx.coverage_3d(map_pts, gt)),
        ("rmse_3d_cm (200k map)", lambda: mx.rmse_3d_cm(map_pts, points)),
        ("bounding_volume_pct (200k map)", lambda: mx.bounding_volume_pct(map_pts, points)),
        ("overlap_3d (3 × 67k)", lambda: mx.overlap_3d(np.array_split(map_pts, 3), gt)),
    ]:
        t, value = timed(fn, args.repeat)
        rows.append((name, t, f"{value:.3f}"))
    # one live time-series sample: coverage, overlap, RMSE, BV with the truth's cached KD-tree
    probe = Probe(GroundTruth(grid, points, seen, seen), EvalConfig())
    probe.surface_tree  # noqa: B018 - built once per run, outside the per-sample cost
    t, quality = timed(lambda: map_quality(probe, map_pts, np.array_split(map_pts, 3)),
                       args.repeat)
    rows.append(("map_quality, one time-series sample (200k)", t,
                 f"coverage {quality['coverage_3d_pct']:.2f} %"))
    lines = ["| step | median s | result |", "|---|---:|---|"]
    lines += [f"| {name} | {t:.3f} | {result} |" for name, t, result in rows]
    log.info("\n".join(lines))


def time_run_folder(run_dir: Path, repeat: int) -> None:
    """The launcher's scoring after the last tick (its probe, ground truth loaded, is warm
    from the mission), and whether it gives the run's metrics.json."""
    config = RunConfig.read(run_dir / "config.yaml")
    probe = probe_for(config.sim)
    def scored() -> dict:
        probe._quality_memo = None  # score the maps, not the memo of the last call
        return evaluate_run_folder(run_dir, probe)

    t_first, metrics = timed(scored, 1)
    t, metrics = timed(scored, repeat)
    t_memo, _ = timed(lambda: evaluate_run_folder(run_dir, probe), repeat)
    same = metrics == {**rf.read_json(run_dir / rf.METRICS), "wall_time_s": metrics["wall_time_s"]}
    log.info("| step | median s | result |\n|---|---:|---|\n"
             "| scoring, first call (trees built) | %.3f | %s |\n"
             "| scoring, warm probe (median of %d) | %.3f | metrics.json reproduced: %s |\n"
             "| the same maps again (the series' last row scored them) | %.3f | |",
             t_first, run_dir.name, repeat, t, same, t_memo)


if __name__ == "__main__":
    main()
