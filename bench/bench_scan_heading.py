"""Heading change between consecutive camera frames: the frames registered to each other
(`scan_odometry.ScanOdometry`) against the wheel odometry, on a finished mission's paths.

Uses bench_localization's rendered frames (cached next to the run; a perfect DRF) and the
simulator's odometry model drawn as in the mission. Per frame step it prints nothing; per run
the median / p90 / p99 / max of |error| in degrees, for all steps and for turning ones
(> 3° between frames), and how often the frames gave no answer.

Run: .venv/bin/python bench/bench_scan_heading.py RUN_DIR... [--robots 0 1]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from bench_localization import load_or_record  # noqa: E402

from services.common.geometry import T_from_xyyaw, wrap_angle  # noqa: E402
from services.evaluator.evaluate import RunConfig  # noqa: E402
from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.params import registration_params  # noqa: E402
from services.robot_agent.projection import cam_to_base, depth_to_points  # noqa: E402
from services.robot_agent.registrar import FrameRegistrar  # noqa: E402
from services.robot_agent.scan_odometry import ScanOdometry, ScanOdometryParams  # noqa: E402
from services.simulator.core import odometry_noise  # noqa: E402
from services.simulator.odometry import WheelOdometry  # noqa: E402

TURNING_RAD = np.radians(3.0)


def heading_errors(run_dir: Path, robot: int) -> np.ndarray:
    """(n, 3): true turn, scan error (nan: no answer), odometry error, rad, per frame step."""
    cfg = AgentConfig()
    sim_cfg = RunConfig.read(run_dir / "config.yaml").sim
    rec = load_or_record(run_dir)
    spawn = tuple(rec.poses[robot, 0])
    odom = WheelOdometry(spawn, odometry_noise(sim_cfg, robot),
                         np.random.default_rng([sim_cfg.seed, 2, robot]))
    registrar = FrameRegistrar(registration_params(cfg))
    scans = ScanOdometry(ScanOdometryParams())
    frame_of = {int(k): f for f, k in enumerate(rec.frame_ticks)}
    rows, prev = [], None
    for t, k in enumerate(rec.ticks):
        true = rec.poses[robot, t]
        o = odom.update(tuple(true), sim_cfg.tick_s)[0] if t > 0 else spawn
        f = frame_of.get(int(k))
        if f is None:
            continue
        depth, mates = rec.depth[robot, f].astype(np.float32), rec.teammate[robot, f]
        cam = depth_to_points(np.where(mates, 0.0, depth), rec.K, cfg.pixel_stride, rec.range_m)
        frame = registrar.cloud_tree(cam_to_base(cam.points_cam, rec.T_base_cam[robot]))
        if frame is None:
            scans.reset()
            prev = None
            continue
        turn = scans.turn(*frame, T_from_xyyaw(*o))
        if prev is not None:
            true_turn = wrap_angle(true[2] - prev[0][2])
            odom_turn = wrap_angle(o[2] - prev[1][2])
            rows.append((true_turn, np.nan if turn is None else wrap_angle(turn - true_turn),
                         wrap_angle(odom_turn - true_turn)))
        prev = (true, o)
    return np.array(rows)


def _stats(err: np.ndarray) -> str:
    e = np.degrees(np.abs(err[~np.isnan(err)]))
    return "median {:.3f} / p90 {:.3f} / p99 {:.3f} / max {:.3f}°".format(
        *np.percentile(e, [50, 90, 99, 100]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dirs", type=Path, nargs="+", help="finished mission folders")
    ap.add_argument("--robots", type=int, nargs="*", help="only these robots")
    args = ap.parse_args()
    every = []
    for run_dir in args.run_dirs:
        n = load_or_record(run_dir).poses.shape[0]
        for r in args.robots or range(n):
            rows = heading_errors(run_dir, r)
            every.append(rows)
            print(f"{run_dir} robot {r}: {len(rows)} steps; frames {_stats(rows[:, 1])}; "
                  f"odometry {_stats(rows[:, 2])}; no answer {np.isnan(rows[:, 1]).mean():.1%}")
    rows = np.concatenate(every)
    turning = np.abs(rows[:, 0]) > TURNING_RAD
    print(f"all {len(rows)} steps: frames {_stats(rows[:, 1])}; odometry {_stats(rows[:, 2])}")
    print(f"turning {turning.sum()} steps: frames {_stats(rows[turning, 1])}; "
          f"odometry {_stats(rows[turning, 2])}; no answer {np.isnan(rows[turning, 1]).mean():.1%}")


if __name__ == "__main__":
    main()
