"""One robot's localizer frame by frame, against the truth, on a recorded mission.

Replays robot R of a `bench_agent_replay.py record` folder (the same agent core, the same
inputs) and prints, for every camera frame between two sim times: the registration outcome,
the share of the frame the DRF took, the heading error after the frame and its σ, what the
walls did (fused / rejected so far, the heading change they made and the error before them),
and the error of what registration measured. The truth is the run folder's
`trajectory_R_gt.tum`, read here only: the agent never sees it.

    .venv/bin/python bench/bench_frame_trace.py REC --robot 1 --from 12.5 --to 24 \
        [--set agent.K=V ...]

With `--set`, the agent replays with those config overrides (open loop: the robot still
drives the recorded path).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_agent_replay as replay_mod  # noqa: E402
from bench_pose_replay import parse_sets  # noqa: E402

from services.common.geometry import wrap_angle, xyyaw_from_T  # noqa: E402
from services.config import load_config  # noqa: E402
from services.robot_agent.agent import AgentCore  # noqa: E402


def true_pose_at(gt: np.ndarray) -> callable:
    """(x, y, yaw)(t) of the nearest ground-truth row (TUM: t x y z qx qy qz qw)."""
    yaws = Rotation.from_quat(gt[:, 4:8]).as_euler("zyx")[:, 0]

    def at(t: float) -> np.ndarray:
        k = int(np.argmin(np.abs(gt[:, 0] - t)))
        return np.array([gt[k, 1], gt[k, 2], yaws[k]])
    return at


def install(core: AgentCore, true_pose, t_from: float, t_to: float, tick_s: float) -> None:
    """Wrap the core's localizer so that each frame in [t_from, t_to] prints one line."""
    loc, state = core.localizer, {"tick": 0, "wall": None}
    wall_heading, update, on_odometry = loc._wall_heading, loc.update, core.on_odometry

    def traced_wall(cloud, guess, T_odom_base):
        out = wall_heading(cloud, guess, T_odom_base)
        state["wall"] = (xyyaw_from_T(guess)[2], xyyaw_from_T(out)[2])
        return out

    def traced_update(points_base, T_odom_base, removed_frac=0.0):
        state["wall"] = None
        out = update(points_base, T_odom_base, removed_frac)
        t = state["tick"] * tick_s
        if t_from <= t <= t_to:
            print(line(t, out, removed_frac, loc, state["wall"], true_pose(t)))
        return out

    def traced_odometry(odom):
        state["tick"] = odom.tick
        return on_odometry(odom)

    loc._wall_heading, loc.update, core.on_odometry = traced_wall, traced_update, traced_odometry


def line(t: float, out, removed: float, loc, wall, pose_true: np.ndarray) -> str:
    yaw_true = float(pose_true[2])

    def err(yaw: float) -> float:
        return math.degrees(wrap_angle(yaw - yaw_true))

    def xy_err(T: np.ndarray) -> str:
        dx, dy = 100 * (xyyaw_from_T(T)[:2] - pose_true[:2])
        return f"({dx:+.1f}, {dy:+.1f}) cm"

    sigma = math.degrees(math.sqrt(loc.P[2, 2]))
    text = (f"t {t:6.1f}  {out.reason or 'accepted':20s} removed {removed:.2f}  yaw error "
            f"{err(xyyaw_from_T(out.T_loc_base)[2]):+.2f}° σ {sigma:.2f}° "
            f"xy {xy_err(out.T_loc_base)}")
    if loc.walls is not None and wall is not None:
        change = math.degrees(wrap_angle(wall[1] - wall[0]))
        text += (f"  walls f{loc.walls.n_fused} r{loc.walls.n_rejected} {change:+.2f}° "
                 f"(error before {err(wall[0]):+.2f}°)")
    if out.T_measured is not None:
        text += (f"  measured {err(xyyaw_from_T(out.T_measured)[2]):+.2f}° "
                 f"{xy_err(out.T_measured)} m² {out.mahalanobis2:.1f}")
    return text + f"  true yaw {math.degrees(yaw_true):.1f}°"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rec", type=Path, help="a bench_agent_replay.py record folder")
    ap.add_argument("--robot", type=int, default=0)
    ap.add_argument("--from", dest="t_from", type=float, default=0.0, help="sim s")
    ap.add_argument("--to", dest="t_to", type=float, default=math.inf, help="sim s")
    ap.add_argument("--set", nargs="*", default=[], help="config overrides, dotted KEY=VALUE")
    args = ap.parse_args()
    overrides = parse_sets(args.set)
    gt_path = args.rec / "run" / f"trajectory_{args.robot}_gt.tum"
    if not gt_path.exists():
        ap.error(f"{gt_path} not found: is {args.rec} a bench_agent_replay.py record folder?")
    true_pose = true_pose_at(np.loadtxt(gt_path, ndmin=2))
    replay_mod.load_config = lambda path, extra: load_config(path, {**extra, **overrides})
    config = replay_mod.load_config(args.rec / "run" / "config.yaml", {})
    replay_mod.instrument = lambda core, timer: install(
        core, true_pose, args.t_from, args.t_to, config.sim.tick_s)
    replay_mod.replay(args.rec, args.robot, None)


if __name__ == "__main__":
    main()
