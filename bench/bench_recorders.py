"""CPU the recorders cost, without a mission: a synthetic stream at the default mission's
rates and sizes (3 robots, 0.1 s ticks, pose + ground truth per robot and tick, a grid and
frontiers every edge tick, a merged cloud every 5 s coverage sample) into each recorder
alone; process CPU seconds (all threads: rerun encodes and writes on its own), medians.

    .venv/bin/python bench/bench_recorders.py --sim-time 258 --repeats 3
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from schemas import messages as m  # noqa: E402
from services.launcher.config import RecordConfig  # noqa: E402
from services.launcher.monitor import RobotTrack  # noqa: E402
from services.launcher.recorders import McapRecorder, Recorders  # noqa: E402
from services.launcher.rerun_recorder import RerunRecorder  # noqa: E402

ROBOTS, TICK_S = 3, 0.1


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def stream(rec: Recorders, tracks: dict[int, RobotTrack], ticks: int, points: int) -> None:
    rng = np.random.default_rng(0)
    cells = rng.choice(np.array([-1, 0, 100], np.int8), size=(300, 320))
    fr = [m.Frontier(frontier_id=i, frontier_class="weak" if i % 3 else "unexplored",
                     centroid=(i * 0.3, 1.0, 0.5), goal_xy=(i * 0.3, 0.5), size=5 + i,
                     gain=1.0, importance=0.5) for i in range(30)]
    for tick in range(ticks):
        stamp = tick * 100_000_000
        for r in range(ROBOTS):
            pose = m.Pose2D(x=0.01 * tick + r, y=0.02 * tick, yaw=0.01 * tick)
            tracks[r].est_stamps_ns.append(stamp)
            tracks[r].est_xyyaw.append((pose.x, pose.y, pose.yaw))
            tracks[r].gt_xyyaw.append((pose.x, pose.y, pose.yaw))
            rec.on_message(m.GtPose(robot_id=r, tick=tick, stamp_ns=stamp, pose_world=pose))
            rec.on_message(m.RobotPose(robot_id=r, tick=tick, stamp_ns=stamp, pose_world=pose,
                                       state="goal"))
        if tick % 10 == 0:
            rec.on_message(m.OccupancyGrid(tick=tick, resolution_m=0.05, origin_x=0.0,
                                           origin_y=0.0, cells=cells))
            rec.on_message(m.Frontiers(tick=tick, frontiers=fr, complete=False,
                                       assigned={0: 1, 1: 2, 2: 3}))
        if tick % 50 == 0 and tick:
            n = int(points * tick / ticks)
            cloud = m.Cloud(tick=tick, points_world=rng.uniform(0, 9, (n, 3)).astype(np.float32),
                            colors=np.zeros((n, 3), np.uint8), robot_ids=np.zeros(n, np.uint8))
            rec.on_sample({"coverage_3d_pct": 50.0, "bounding_volume_pct": 0.0}, cloud)


def one(kind: str, ticks: int, points: int, tmp: Path) -> tuple[float, float, int]:
    """(CPU s, wall s, file bytes) of one recorder on the synthetic mission."""
    tracks = {r: RobotTrack() for r in range(ROBOTS)}
    cfg = RecordConfig()
    path = tmp / f"{kind}.out"
    cpu0, wall0 = _cpu(), time.monotonic()
    sink = McapRecorder(path, ROBOTS, cfg, TICK_S) if kind == "mcap" else RerunRecorder(
        path, ROBOTS, cfg, TICK_S, None, f"bench-{time.time_ns()}", tracks)
    rec = Recorders([sink])
    stream(rec, tracks, ticks, points)
    rec.close()
    return _cpu() - cpu0, time.monotonic() - wall0, path.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sim-time", type=float, default=258.0)
    parser.add_argument("--points", type=int, default=300_000, help="final merged cloud size")
    parser.add_argument("--repeats", type=int, default=3)
    opts = parser.parse_args()
    ticks = round(opts.sim_time / TICK_S)
    import rerun  # noqa: F401  (its import, ~1 s, is paid once per launcher, not counted here)

    print(f"synthetic mission: {ROBOTS} robots, {ticks} ticks, clouds up to {opts.points} "
          f"points; medians of {opts.repeats}\n")
    print("| recorder | CPU s | wall s | file MB |\n|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("mcap", "rrd"):
            runs = [one(kind, ticks, opts.points, Path(tmp)) for _ in range(opts.repeats)]
            cpu, wall, size = (statistics.median(col) for col in zip(*runs, strict=True))
            print(f"| {kind} | {cpu:.2f} | {wall:.2f} | {size / 1e6:.1f} |")


if __name__ == "__main__":
    main()
