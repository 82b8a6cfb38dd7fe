"""Is a mission's pose error the robots' own, or the whole fleet's? From run folders.

For each run, each robot's final estimated position (`trajectory_R_est.tum`) against the
truth (`trajectory_R_gt.tum`), split along the straight line from its start to where it truly
ended (radial: negative = the estimate fell short, toward the start) and across it (lateral:
positive = to the left), in cm and in % of that distance; medians over the robots. An error
shared by every robot in one direction (the fleet's) is one that inter-robot registrations
cannot see: the robots agree with each other and are all wrong together.

With `--affine`, every pose of every robot instead: the fleet's error as one affine map of
the position (error = A · truth + t, least squares over all poses), i.e. the whole fleet's
map stretched (A's symmetric part: scale per axis, in cm per m) and turned (its
antisymmetric part), the pose error left once that is taken out, and the merged map's BV,
RMSE and 3D coverage with the same map taken out of its points: how much of a mission's
ghosting is the fleet's shared distortion rather than robots disagreeing.

    .venv/bin/python bench/bench_fleet_drift.py RUN [RUN ...]
    .venv/bin/python bench/bench_fleet_drift.py --affine RUN [RUN ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_merger_replay import read_tum  # noqa: E402


def final_errors(run: Path) -> np.ndarray:
    """(robots, 5): distance from start m, radial cm, lateral cm, x cm, y cm."""
    rows = []
    for est_path in sorted(run.glob("trajectory_*_est.tum")):
        est = read_tum(est_path)
        gt = read_tum(est_path.with_name(est_path.name.replace("_est", "_gt")))
        n = min(len(est), len(gt))
        span = gt[n - 1, 1:3] - gt[0, 1:3]
        dist = float(np.linalg.norm(span))
        if dist < 1.0:
            continue  # a robot that ended where it began has no direction to split along
        u = span / dist
        e = est[n - 1, 1:3] - gt[n - 1, 1:3]
        rows.append((dist, 100 * float(e @ u), 100 * float(u[0] * e[1] - u[1] * e[0]),
                     100 * e[0], 100 * e[1]))
    return np.array(rows)


def fleet_affine(truth_xy: np.ndarray, est_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A (2, 2), t (2,)) with est − truth ≈ truth @ A.T + t over (N, 2) positions."""
    design = np.column_stack([truth_xy, np.ones(len(truth_xy))])
    coef, *_ = np.linalg.lstsq(design, est_xy - truth_xy, rcond=None)
    return coef[:2].T, coef[2]


def _all_poses(run: Path) -> tuple[np.ndarray, np.ndarray]:
    truth, est = [], []
    for est_path in sorted(run.glob("trajectory_*_est.tum")):
        e = read_tum(est_path)
        g = read_tum(est_path.with_name(est_path.name.replace("_est", "_gt")))
        n = min(len(e), len(g))
        truth.append(g[:n, 1:3])
        est.append(e[:n, 1:3])
    return np.concatenate(truth), np.concatenate(est)


def affine_row(run: Path) -> str:
    from services.evaluator import run_files
    from services.evaluator.evaluate import RunConfig, probe_for
    from services.evaluator.scoring import map_quality

    truth, est = _all_poses(run)
    A, t = fleet_affine(truth, est)
    rest = est - truth - (truth @ A.T + t)
    rms = lambda d: 100 * float(np.sqrt(np.mean(np.sum(d**2, axis=1))))  # noqa: E731
    probe = probe_for(RunConfig.read(run / "config.yaml").sim)
    points = run_files.read_ply(run / "merged_map.ply")
    # the map's points lie where the estimate put them: truth ≈ (est − t) (I + A)^-1
    undone = points.copy()
    undone[:, :2] = (points[:, :2] - t) @ np.linalg.inv(np.eye(2) + A).T
    q0 = map_quality(probe, points, None)
    q1 = map_quality(probe, undone, None)
    turn_deg = np.degrees(0.5 * (A[1, 0] - A[0, 1]))
    return (f"| {run} | {100 * A[0, 0]:+.3f} | {100 * A[1, 1]:+.3f} | {turn_deg:+.3f} | "
            f"{100 * t[0]:+.1f}, {100 * t[1]:+.1f} | "
            f"{rms(est - truth):.2f} → {rms(rest):.2f} | "
            f"{q0['bounding_volume_pct']:.3f} → {q1['bounding_volume_pct']:.3f} | "
            f"{q0['rmse_3d_cm']:.2f} → {q1['rmse_3d_cm']:.2f} | "
            f"{q0['coverage_3d_pct']:.2f} → {q1['coverage_3d_pct']:.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--affine", action="store_true",
                        help="the fleet's error as one affine map of the position")
    args = parser.parse_args()
    if args.affine:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        print("| run | x stretch cm/m | y stretch cm/m | turn ° | shift cm | pose error rms cm "
              "(as is → affine out) | BV % | RMSE cm | 3D cov % |\n"
              "|---|---:|---:|---:|---|---|---|---|---|")
        for run in args.runs:
            print(affine_row(run))
        return
    print("| run | robots | radial cm | lateral cm | x cm | y cm | radial % | lateral % | "
          "robots short of the truth |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for run in args.runs:
        e = final_errors(run)
        if not len(e):
            print(f"| {run} | 0 | | | | | | | |")
            continue
        med = np.median(e, axis=0)
        print(f"| {run} | {len(e)} | {med[1]:.1f} | {med[2]:.1f} | {med[3]:.1f} | {med[4]:.1f} | "
              f"{np.median(e[:, 1] / e[:, 0]):.3f} | {np.median(e[:, 2] / e[:, 0]):.3f} | "
              f"{int((e[:, 1] < 0).sum())} |")


if __name__ == "__main__":
    main()
