"""DRF replay: which teammate pixels did the agents' filter let through in a finished mission?

Replays the frames of a run folder (rendered on the recorded true paths, see
bench_localization.py) through mutual awareness and the DRF with exactly what the agents had:
each observer's own estimate (`trajectory_<r>_est.tum`) and its teammates' published
estimates of the tick before, extrapolated as the agent does. Against the simulator's
segmentation it reports teammate pixels kept per robot, and every frame that leaked, with the
teammate's distance, bearing, whether awareness put it in view, and the estimate's error.

Run: .venv/bin/python bench/bench_drf_replay.py RUN_DIR [--set drf_c=0.3 ...]
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_localization import load_or_record  # noqa: E402

from schemas.messages import Pose2D, RobotPose  # noqa: E402
from services.evaluator import run_files as rf  # noqa: E402
from services.robot_agent.awareness import in_view_partial  # noqa: E402
from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.drf import filter_mask  # noqa: E402
from services.robot_agent.params import drf_params  # noqa: E402
from services.robot_agent.projection import hfov_of  # noqa: E402
from services.robot_agent.teammates import predict_xy  # noqa: E402

log = logging.getLogger("bench_drf_replay")


def pose_msg(robot: int, tick: int, xyyaw: np.ndarray) -> RobotPose:
    return RobotPose(robot_id=robot, tick=tick, stamp_ns=0, pose_world=Pose2D(
        x=float(xyyaw[0]), y=float(xyyaw[1]), yaw=float(xyyaw[2])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--set", nargs="*", default=[], help="AgentConfig overrides, key=value")
    ap.add_argument("--min-pixels", type=int, default=5, help="list leaks of this many pixels")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = AgentConfig(**{k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.set)})
    rec = load_or_record(args.run_dir)
    n_robots = rec.poses.shape[0]
    est = [rf.read_tum(rf.est_trajectory_path(args.run_dir, r))[1] for r in range(n_robots)]
    params = drf_params(cfg)
    tick_index = {int(k): t for t, k in enumerate(rec.ticks)}
    for r in range(n_robots):
        kept = total = 0
        for f, k in enumerate(rec.frame_ticks):
            t = tick_index[int(k)]
            if t < 2:
                continue
            depth = rec.depth[r, f].astype(np.float32)
            mates = rec.teammate[r, f] & (depth <= rec.range_m)
            if not mates.any():
                continue
            pose_obs = tuple(est[r][t])
            xy, ids = [], []
            for o in range(n_robots):
                if o != r:
                    xy.append(predict_xy(pose_msg(o, k - 1, est[o][t - 1]),
                                         pose_msg(o, k - 2, est[o][t - 2]), int(k),
                                         cfg.predict_max_ticks))
                    ids.append(o)
            xy = np.array(xy)
            seen = in_view_partial(pose_obs, xy, radius_m=cfg.robot_size_m,
                                   fov_rad=hfov_of(rec.K, depth.shape[1]),
                                   range_m=rec.range_m, c=cfg.drf_c)
            mask = filter_mask(depth, rec.K, rec.T_base_cam[r], pose_obs, xy[seen], params)
            leak = mates & ~mask
            total += int(mates.sum())
            kept += int(leak.sum())
            if leak.sum() >= args.min_pixels:
                report_leak(r, int(k), rec, t, pose_obs, xy, ids, seen, depth, leak)
        log.info("robot %d: teammate pixels kept %d of %d (%.2f %%)", r, kept, total,
                 100.0 * kept / max(total, 1))


def report_leak(r, k, rec, t, pose_obs, xy, ids, seen, depth, leak) -> None:
    parts = []
    for j, o in enumerate(ids):
        true = rec.poses[o, t]
        rel = true[:2] - rec.poses[r, t, :2]
        bearing = math.degrees(math.atan2(rel[1], rel[0]) - rec.poses[r, t, 2])
        bearing = (bearing + 180) % 360 - 180
        parts.append(f"mate {o}: d {np.hypot(*rel):.2f} m bearing {bearing:+.0f}° "
                     f"in view {bool(seen[j])} est err {np.hypot(*(xy[j] - true[:2])):.3f} m")
    rows, cols = np.nonzero(leak)
    log.info("robot %d tick %d: %d px leaked (depth %.2f-%.2f m, cols %d-%d, rows %d-%d); %s",
             r, k, leak.sum(), depth[leak].min(), depth[leak].max(), cols.min(), cols.max(),
             rows.min(), rows.max(), "; ".join(parts))


if __name__ == "__main__":
    main()
