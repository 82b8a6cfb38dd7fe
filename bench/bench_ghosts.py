"""Where do the ghosts of a mission's merged map come from? (SPEC §5 bounding volume)

Loads `<run>/merged_map.ply`, marks ghost points (> 0.10 m from every static surface, the
evaluator's rule), clusters them (DBSCAN) and prints each cluster's centre, size, z range,
which robots' own maps hold it, and which robot's ground-truth trajectory passed through it
(and when): a cluster where a teammate stood is a DRF leak, a thin shell 0.10-0.15 m off a
surface is pose error. Per robot: the ghost voxels of its own map, its pose error and the
odometry errors its agent had learned by its last report (agent log): the robots whose maps
hold the ghosts, and why. With `--mission`, first runs the mission itself.

    .venv/bin/python bench/bench_ghosts.py /tmp/x
    .venv/bin/python bench/bench_ghosts.py /tmp/x --mission -- --robots 3 --sim-time 120
"""

from __future__ import annotations

import argparse
import logging
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from services.evaluator.evaluate import RunConfig, probe_for  # noqa: E402
from services.evaluator.metrics import bounding_volume_pct  # noqa: E402
from services.evaluator.run_files import read_ply, read_tum  # noqa: E402

log = logging.getLogger("bench_ghosts")
GHOST_M = 0.10
ROBOT_R = 0.25  # a cluster this close to a robot's true path may be that robot


def _clusters(points: np.ndarray, eps: float) -> np.ndarray:
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    return np.asarray(cloud.cluster_dbscan(eps, 3, False))


def learned_odometry(run: Path, robot: int) -> str:
    """The odometry errors robot's agent last reported learning (its log), or '-'."""
    log_file = run / "logs" / f"agent{robot}.log"
    found = re.findall(r"odometry errors OdometryErrors\(scale=(\S+), turn_scale=(\S+), "
                       r"heading_bias_rad_per_m=(\S+)\) from (\d+) segments",
                       log_file.read_text() if log_file.exists() else "")
    if not found:
        return "-"
    scale, turn, bias, n = found[-1]
    return (f"scale {100 * float(scale):+.2f} %, turn {100 * float(turn):+.2f} %, "
            f"bias {1000 * float(bias):+.2f} mrad/m ({n} segments)")


def analyse(run: Path, eps: float = 0.12, top: int = 15) -> dict[str, float]:
    merged = read_ply(run / "merged_map.ply")
    probe = probe_for(RunConfig.read(run / "config.yaml").sim)  # the run's own world
    surface = probe.gt.surface_points_world
    dist, _ = cKDTree(surface).query(merged)
    ghost = dist > GHOST_M
    bv = bounding_volume_pct(merged, surface)
    shell = ghost & (dist <= 0.15)
    print(f"{run}: {merged.shape[0]} points, BV {bv:.4f} %, ghost points {ghost.sum()} "
          f"({100.0 * shell.sum() / max(ghost.sum(), 1):.0f} % within 0.10-0.15 m: pose error)")
    robot_maps = {}
    trajs = {}
    for n in range(64):
        if not (run / f"robot_{n}_map.ply").exists():
            break
        own = read_ply(run / f"robot_{n}_map.ply")
        robot_maps[n] = cKDTree(own)
        _, n_ghost, n_voxels = probe.ghost_point_mask(own, probe.surface_distance(own))
        t, xyyaw = read_tum(run / f"trajectory_{n}_gt.tum")
        trajs[n] = (t, xyyaw)
        te, est = read_tum(run / f"trajectory_{n}_est.tum")
        k = np.searchsorted(te, t).clip(0, len(te) - 1)
        err = np.hypot(*(est[k, :2] - xyyaw[:, :2]).T)
        yaw = np.abs(np.angle(np.exp(1j * (est[k, 2] - xyyaw[:, 2]))))
        print(f"  robot {n}: own map {n_ghost} ghost voxels of {n_voxels}; pose error final "
              f"{err[-1]:.3f} m, max {err.max():.3f} m, mean {err.mean():.3f} m; yaw max "
              f"{np.degrees(yaw.max()):.1f} deg; learned {learned_odometry(run, n)}")
    gp = merged[ghost]
    if gp.shape[0] == 0:
        return {"bv_pct": bv, "ghost_points": 0}
    labels = _clusters(gp, eps)
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    order = np.argsort(-sizes)[:top]
    print("  pts  centre (x, y)   extent  z range     d_surf  mapped by  robot there (t s)")
    for i in order:
        pts = gp[labels == ids[i]]
        c = pts.mean(axis=0)
        ext = float(np.hypot(*(pts[:, :2].max(0) - pts[:, :2].min(0))))
        by = [n for n, tree in robot_maps.items() if np.isfinite(
            tree.query(pts, distance_upper_bound=0.03)[0]).mean() > 0.5]
        there = []
        for n, (t, xy) in trajs.items():
            near = np.hypot(*(xy[:, :2] - c[None, :2]).T) < ROBOT_R
            if near.any():
                there.append(f"r{n} {t[near].min():.1f}-{t[near].max():.1f}")
        d = dist[ghost][labels == ids[i]]
        print(f"{pts.shape[0]:5d}  ({c[0]:6.2f}, {c[1]:6.2f})  {ext:5.2f}  "
              f"{pts[:, 2].min():.2f}-{pts[:, 2].max():.2f}  {np.median(d):.2f}    "
              f"{by!s:9s}  {', '.join(there)}")
    return {"bv_pct": bv, "ghost_points": int(ghost.sum())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("run", type=Path)
    ap.add_argument("--mission", action="store_true", help="run `spacemap run --out RUN` first")
    ap.add_argument("--eps", type=float, default=0.12)
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("extra", nargs="*", help="after --: extra `spacemap run` arguments")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO)
    if args.mission:
        exe = Path(sys.executable).with_name("spacemap")
        subprocess.run([str(exe), "run", "--out", str(args.run), *args.extra], check=True)
    analyse(args.run, args.eps, args.top)


if __name__ == "__main__":
    main()
