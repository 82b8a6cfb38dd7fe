"""Does a chord of wheel odometry measure the wheels' scale? From a recorded mission.

The odometry calibration (services/robot_agent/odometry_calibration.py) learns the wheels'
scale from segments: odometry's chord between two well-registered frames against the
registered one. This script asks the question without registration: over windows of W s of
every robot of a recording (`bench/bench_agent_replay.py record`), the least-squares scale of
odometry's chord against the truth's chord (`run/trajectory_R_gt.tum`), with the chord taken
from the two raw poses and from the increments with the turn errors taken out (the
simulator's own turn scale and heading bias, or those given). Where the wheels over-turn,
the raw path bends more than the true one and its chord is short: the longer the window
(the more it turns), the further the raw chords' scale falls below the wheels'.

    .venv/bin/python bench/bench_odometry_chords.py /tmp/rec_wh --windows 2 5 10 30
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_agent_replay import LOG, read_log  # noqa: E402
from bench_merger_replay import read_tum  # noqa: E402

from schemas.codec import decode  # noqa: E402
from schemas.messages import Odometry  # noqa: E402
from services.config import load_config  # noqa: E402
from services.robot_agent.odometry_calibration import (  # noqa: E402
    OdometryErrors,
    _compose,
    _relative,
    turn_corrected_increment,
)


def chord_scale(odom_chords: np.ndarray, true_chords: np.ndarray) -> float:
    """Least-squares s in odom ≈ (1 + s) · true."""
    return float(np.sum(true_chords * (odom_chords - true_chords)) / np.sum(true_chords**2))


def window_chords(odom: np.ndarray, truth_xy: np.ndarray, ticks: int,
                  errors: OdometryErrors) -> np.ndarray:
    """(n, 3) raw chord, turn-corrected chord and true chord of consecutive windows of
    `ticks` ticks; `odom` (T, 3) raw poses, `truth_xy` (T, 2) at the same ticks."""
    incs = [turn_corrected_increment(_relative(odom[i], odom[i + 1]), errors)
            for i in range(len(odom) - 1)]
    rows = []
    for i0 in range(0, len(odom) - ticks, ticks):
        path = np.zeros(3)
        for inc in incs[i0:i0 + ticks]:
            path = _compose(path, inc)
        rows.append((np.hypot(*(odom[i0 + ticks, :2] - odom[i0, :2])), np.hypot(*path[:2]),
                     np.hypot(*(truth_xy[i0 + ticks] - truth_xy[i0]))))
    return np.array(rows).reshape(-1, 3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rec", type=Path)
    ap.add_argument("--windows", type=float, nargs="+", default=[2.0, 5.0, 10.0, 30.0])
    ap.add_argument("--turn-scale", type=float, default=None)
    ap.add_argument("--heading-bias", type=float, default=None)
    args = ap.parse_args()
    sim = load_config(args.rec / "run" / "config.yaml", {}).sim
    errors = OdometryErrors(0.0, sim.odom_yaw_scale_error if args.turn_scale is None
                            else args.turn_scale,
                            sim.odom_heading_bias_rad_per_m if args.heading_bias is None
                            else args.heading_bias)
    odom: dict[int, dict[int, tuple[float, float, float]]] = {}
    for key, payload in read_log(args.rec / LOG):
        if key.endswith("/odom"):
            m = decode(payload, Odometry)
            odom.setdefault(m.robot_id, {})[m.tick] = (m.pose_odom.x, m.pose_odom.y,
                                                       m.pose_odom.yaw)
    print(f"wheels: scale {sim.odom_scale_error:.2%} (the simulator's); turn errors taken out: "
          f"turn scale {errors.turn_scale:.2%}, heading bias {errors.heading_bias_rad_per_m} "
          "rad/m\n\n| window s | windows | scale from raw chords % | from turn-corrected "
          "chords % |\n|---:|---:|---:|---:|")
    for window in args.windows:
        ticks = int(round(window / sim.tick_s))
        rows = []
        for robot, poses in sorted(odom.items()):
            gt = read_tum(args.rec / "run" / f"trajectory_{robot}_gt.tum")
            truth = {int(round(t / sim.tick_s)): (x, y) for t, x, y in gt[:, :3]}
            kept = [t for t in sorted(poses) if t in truth]
            rows.append(window_chords(np.array([poses[t] for t in kept]),
                                      np.array([truth[t] for t in kept]), ticks, errors))
        c = np.concatenate(rows)
        c = c[c[:, 2] > 0.3]  # windows that went somewhere
        print(f"| {window:g} | {len(c)} | {100 * chord_scale(c[:, 0], c[:, 2]):.3f} | "
              f"{100 * chord_scale(c[:, 1], c[:, 2]):.3f} |")


if __name__ == "__main__":
    main()
