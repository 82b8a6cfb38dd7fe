"""The heading a frame's walls give (`wall_heading.wall_direction`) against the truth, on a
finished mission's paths.

Uses bench_localization's rendered frames (cached next to the run; realistic depth noise, a
perfect DRF). Per robot: how many frames give a direction, and the |error| of true heading +
the frame's wall direction against the world's direction (modulo 90°; the world's is the
circular mean over all the robot's frames, printed), median / p90 / p99 / max in degrees.

Run: .venv/bin/python bench/bench_wall_heading.py RUN_DIR... [--robots 0 1]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from bench_localization import load_or_record  # noqa: E402

from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.params import registration_params  # noqa: E402
from services.robot_agent.projection import cam_to_base, depth_to_points  # noqa: E402
from services.robot_agent.registrar import FrameRegistrar  # noqa: E402
from services.robot_agent.wall_heading import WallHeadingParams, fold, wall_direction  # noqa: E402


def world_directions(run_dir: Path, robot: int, params: WallHeadingParams) -> np.ndarray:
    """(frames,): true heading + the frame's wall direction, rad (nan: no direction)."""
    cfg = AgentConfig()
    rec = load_or_record(run_dir)
    registrar = FrameRegistrar(registration_params(cfg))
    frame_of = {int(k): f for f, k in enumerate(rec.frame_ticks)}
    out = []
    for t, k in enumerate(rec.ticks):
        f = frame_of.get(int(k))
        if f is None:
            continue
        depth, mates = rec.depth[robot, f].astype(np.float32), rec.teammate[robot, f]
        cam = depth_to_points(np.where(mates, 0.0, depth), rec.K, cfg.pixel_stride, rec.range_m)
        frame = registrar.cloud_tree(cam_to_base(cam.points_cam, rec.T_base_cam[robot]))
        d = None
        if frame is not None:
            d = wall_direction(frame[0].points()[:, :3], frame[0].normals()[:, :3], params)
        out.append(np.nan if d is None else float(fold(rec.poses[robot, t, 2] + d.angle_rad)))
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dirs", type=Path, nargs="+", help="finished mission folders")
    ap.add_argument("--robots", type=int, nargs="*", help="only these robots")
    args = ap.parse_args()
    params = WallHeadingParams()
    for run_dir in args.run_dirs:
        n_robots = load_or_record(run_dir).poses.shape[0]
        for robot in args.robots if args.robots is not None else range(n_robots):
            w = world_directions(run_dir, robot, params)
            ok = np.isfinite(w)
            ref = float(np.angle(np.exp(4j * w[ok]).mean()) / 4.0)
            err = np.abs(np.degrees(fold(w[ok] - ref)))
            p50, p90, p99 = np.percentile(err, [50, 90, 99])
            print(f"{run_dir.name} robot {robot}: {ok.sum()}/{len(w)} frames; world "
                  f"{np.degrees(ref):+.2f}°; |error| ° median {p50:.3f} p90 {p90:.3f} "
                  f"p99 {p99:.3f} max {err.max():.2f}")


if __name__ == "__main__":
    main()
