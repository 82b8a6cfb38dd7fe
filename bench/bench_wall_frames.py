"""The heading each frame's walls give, against the truth, on the frames a mission's agents saw.

Replays robots of a `bench_agent_replay.py record` folder (the agents' own inputs: realistic
depth, what the DRF left, the registrar's downsampled points and normals), keeps every
frame the wall heading was asked about, and scores `wall_heading.wall_direction` on them
under one or more settings of `WallHeadingParams` (`--compare FIELD=VALUE[,FIELD=VALUE]`;
`default` for the defaults): per setting, the frames that give a direction and the |error|
of the heading it gives (the robot's learned world direction, branch nearest the true
heading) against the true heading, median / p90 / p99 / max, and the frames over 0.6° and 1°
with their robot and sim time. The truth is the recording's `trajectory_R_gt.tum`, read here
only. Frames are scored offline, so settings compare on the very same frames.

    .venv/bin/python bench/bench_wall_frames.py REC --robots 0,1,2 \\
        --compare along_gap_m=0 default
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_agent_replay as replay_mod  # noqa: E402
from bench_frame_trace import true_pose_at  # noqa: E402

from services.common.geometry import wrap_angle, xyyaw_from_T  # noqa: E402
from services.robot_agent.wall_heading import (  # noqa: E402
    WallHeadingParams,
    heading_from,
    wall_direction,
)


def frames_of(rec: Path, robot: int) -> list[dict]:
    """Each frame the robot's wall heading saw: points, normals (base), predicted and true
    heading, the learned world direction (None while learning)."""
    true_pose = true_pose_at(np.loadtxt(rec / "run" / f"trajectory_{robot}_gt.tum", ndmin=2))
    tick_s = replay_mod.load_config(rec / "run" / "config.yaml", {}).sim.tick_s
    out: list[dict] = []

    def install(core, _timer) -> None:
        loc, state = core.localizer, {"tick": 0}
        wall_heading, on_odometry = loc._wall_heading, core.on_odometry

        def traced(cloud, guess, T_odom_base):
            t = state["tick"] * tick_s
            out.append(dict(t=t, robot=robot, points=cloud.points()[:, :3].copy(),
                            normals=cloud.normals()[:, :3].copy(),
                            yaw_pred=float(xyyaw_from_T(guess)[2]),
                            yaw_true=float(true_pose(t)[2]), world=loc.walls.world_rad))
            return wall_heading(cloud, guess, T_odom_base)

        def ticked(odom):
            state["tick"] = odom.tick
            return on_odometry(odom)

        loc._wall_heading, core.on_odometry = traced, ticked

    replay_mod.instrument = install
    replay_mod.replay(rec, robot, None)
    return out


def parse_setting(text: str) -> WallHeadingParams:
    params = WallHeadingParams()
    if text == "default":
        return params
    types = {f.name: f.type for f in fields(WallHeadingParams)}
    changes = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        if not sep or key not in types:
            raise SystemExit(f"--compare {item!r}: expected FIELD=VALUE, FIELD one of "
                             f"{sorted(types)}")
        changes[key] = int(value) if str(types[key]).startswith("int") else float(value)
    return replace(params, **changes)


def score(frames: list[dict], params: WallHeadingParams) -> tuple[np.ndarray, list[str]]:
    """(|errors| in degrees, 'robot@t: error' of those over 0.6°)."""
    errors, far = [], []
    for f in frames:
        if f["world"] is None:
            continue
        d = wall_direction(f["points"], f["normals"], params)
        if d is None:
            continue
        err = math.degrees(wrap_angle(heading_from(d, f["world"], f["yaw_pred"]) - f["yaw_true"]))
        errors.append(abs(err))
        if abs(err) > 0.6:
            far.append(f"r{f['robot']}@{f['t']:.1f}s {err:+.2f}°")
    return np.asarray(errors), far


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rec", type=Path, nargs="+", help="bench_agent_replay.py record folders")
    ap.add_argument("--robots", default="0", help="comma-separated robot ids")
    ap.add_argument("--compare", nargs="+", default=["default"],
                    help="settings: default, or FIELD=VALUE[,FIELD=VALUE] of WallHeadingParams")
    args = ap.parse_args()
    frames = [f for rec in args.rec for r in args.robots.split(",") for f in frames_of(rec, int(r))]
    for text in args.compare:
        e, far = score(frames, parse_setting(text))
        p50, p90, p99 = np.percentile(e, [50, 90, 99])
        print(f"{text}: {len(e)} of {len(frames)} frames give a direction; |error| median "
              f"{p50:.3f}° p90 {p90:.3f}° p99 {p99:.3f}° max {e.max():.2f}°; over 0.6°: "
              f"{len(far)}, over 1°: {int((e > 1).sum())}")
        if far:
            print("    " + ", ".join(far))


if __name__ == "__main__":
    main()
