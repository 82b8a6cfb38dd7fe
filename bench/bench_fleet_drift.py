"""Is a mission's pose error the robots' own, or the whole fleet's? From run folders.

For each run, each robot's final estimated position (`trajectory_R_est.tum`) against the
truth (`trajectory_R_gt.tum`), split along the straight line from its start to where it truly
ended (radial: negative = the estimate fell short, toward the start) and across it (lateral:
positive = to the left), in cm and in % of that distance; medians over the robots. An error
shared by every robot in one direction (the fleet's) is one that inter-robot registrations
cannot see: the robots agree with each other and are all wrong together.

    .venv/bin/python bench/bench_fleet_drift.py RUN [RUN ...]
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+")
    args = parser.parse_args()
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
