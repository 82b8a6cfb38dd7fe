"""Where a mission's pose error grows: along the direction of travel or across it, per robot.

Reads a finished run's TUM files (trajectory_R_gt.tum, trajectory_R_est.tum). For each robot
the error increments of each step are projected on the true direction of motion and summed:
positive = the estimate ran ahead of the robot, negative = it lagged. Divided by the distance
driven it is a scale-like drift (% per metre). Ground truth is read here, in the evaluator's
place, never by an agent.

    .venv/bin/python bench/bench_drift_along.py RUN_DIR...
    # the same per window of sim time (s): where in the mission the estimates ran ahead
    .venv/bin/python bench/bench_drift_along.py --windows 0,25,50,100 RUN_DIR...
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def along_track(gt_xy: np.ndarray, est_xy: np.ndarray) -> tuple[float, float, float]:
    """(along-track error growth m, across-track |growth| m, distance driven m)."""
    step = np.diff(gt_xy, axis=0)
    d_err = np.diff(est_xy - gt_xy, axis=0)
    length = np.linalg.norm(step, axis=1)
    moving = length > 1e-4
    u = step[moving] / length[moving, None]
    along = float(np.einsum("ij,ij->i", d_err[moving], u).sum())
    across = float(np.abs(u[:, 0] * d_err[moving, 1] - u[:, 1] * d_err[moving, 0]).sum())
    return along, across, float(length.sum())


def windowed_growth(gt: np.ndarray, est: np.ndarray, edges_s: list[float],
                    ) -> list[tuple[float, float]]:
    """(along-track growth m, distance m) of one robot per window [edges[i], edges[i+1]) of
    sim time (the last window open-ended), from (N, 8) TUM rows."""
    out = []
    for lo, hi in zip(edges_s, [*edges_s[1:], np.inf], strict=True):
        idx = np.flatnonzero((gt[:, 0] >= lo) & (gt[:, 0] < hi))
        if len(idx) < 2:
            out.append((0.0, 0.0))
            continue
        idx = np.append(idx, min(idx[-1] + 1, len(gt) - 1))  # the step out of the window
        along, _, dist = along_track(gt[idx, 1:3], est[idx, 1:3])
        out.append((along, dist))
    return out


def _print_windows(run: Path, edges_s: list[float]) -> None:
    sums = np.zeros((len(edges_s), 2))
    for gt_path in sorted(run.glob("trajectory_*_gt.tum")):
        est_path = gt_path.with_name(gt_path.name.replace("_gt", "_est"))
        gt, est = np.loadtxt(gt_path, ndmin=2), np.loadtxt(est_path, ndmin=2)
        n = min(len(gt), len(est))
        sums += np.array(windowed_growth(gt[:n], est[:n], edges_s))
    cells = [f"{lo:g}-{hi:g} s {100 * a / max(d, 1e-9):+.2f} % of {d:.0f} m"
             for (a, d), lo, hi in zip(sums, edges_s, [*edges_s[1:], np.inf], strict=True)]
    print(f"{run.name}: along-track growth, fleet, per window: " + "; ".join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--windows", default="", help="comma-separated window starts, sim s")
    args = ap.parse_args()
    for run in args.runs:
        if args.windows:
            _print_windows(run, [float(v) for v in args.windows.split(",")])
            continue
        growth, driven = [], []
        for gt_path in sorted(run.glob("trajectory_*_gt.tum"),
                              key=lambda p: int(p.stem.split("_")[1])):
            est_path = gt_path.with_name(gt_path.name.replace("_gt", "_est"))
            gt, est = np.loadtxt(gt_path, ndmin=2), np.loadtxt(est_path, ndmin=2)
            n = min(len(gt), len(est))
            along, _, dist = along_track(gt[:n, 1:3], est[:n, 1:3])
            growth.append(along)
            driven.append(dist)
        g = np.array(growth) * 100
        per_robot = np.round(g).astype(int).tolist()
        print(f"{run.name}: along-track error growth per robot cm {per_robot}; "
              f"{g.sum() / max(sum(driven), 1e-9):+.2f} % of the distance driven")


if __name__ == "__main__":
    main()
