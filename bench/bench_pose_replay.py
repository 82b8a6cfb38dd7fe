"""Every robot of an agent recording replayed with config overrides: pose error against truth.

`bench_agent_replay.py record` keeps every message a mission's agents read. Replaying each
robot's agent on them with `--set agent.K=V` shows what a localization setting would have
done to the same frames and odometry, in a minute for 24 robots, before any mission is run.
The replay is open loop: the robots drive the recorded paths and their teammates' poses are
the recorded ones, so a setting that changes where robots go shows its effect on paths only
in missions. The truth is the recording's `trajectory_R_gt.tum`, read here only.

    .venv/bin/python bench/bench_pose_replay.py REC [--set agent.reg_sigma_m=0.01 ...]
"""

from __future__ import annotations

import argparse
import sys
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_agent_replay as replay_mod  # noqa: E402

from schemas.messages import RobotPose  # noqa: E402
from services.config import load_config  # noqa: E402

FAR_CM = (8.0, 10.0)  # error thresholds counted per robot (a ghost is > 10 cm off a surface)


def parse_sets(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item!r}: expected KEY=VALUE")
        out[key] = value
    return out


def robot_errors(rec: Path, robot: int, overrides: dict[str, str]) -> np.ndarray:
    """(N,) position error in cm of each pose the replayed agent published."""
    poses: list[tuple[float, float, float]] = []
    encode = replay_mod.encode

    def keep(msg):
        if isinstance(msg, RobotPose) and msg.robot_id == robot:
            poses.append((msg.stamp_ns * 1e-9, msg.pose_world.x, msg.pose_world.y))
        return encode(msg)

    replay_mod.encode = keep
    replay_mod.load_config = lambda path, extra: load_config(path, {**extra, **overrides})
    replay_mod.replay(rec, robot, None)
    gt = np.loadtxt(rec / "run" / f"trajectory_{robot}_gt.tum", ndmin=2)
    est = np.asarray(poses)
    row = np.clip(np.searchsorted(gt[:, 0], est[:, 0] - 1e-6), 0, len(gt) - 1)
    return 100.0 * np.hypot(est[:, 1] - gt[row, 1], est[:, 2] - gt[row, 2])


def _one(args: tuple[Path, int, dict[str, str]]) -> tuple[int, float, float]:
    rec, robot, overrides = args
    err = robot_errors(rec, robot, overrides)
    return robot, float(np.sqrt(np.mean(err**2))), float(err.max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rec", type=Path, help="a bench_agent_replay.py record folder")
    ap.add_argument("--set", nargs="*", default=[], help="config overrides, dotted KEY=VALUE")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    overrides = parse_sets(args.set)
    robots = load_config(args.rec / "run" / "config.yaml", {}).sim.robots
    with Pool(args.jobs) as pool:
        rows = pool.map(_one, [(args.rec, r, overrides) for r in range(robots)])
    rms, worst = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    print("max error per robot, cm: " + " ".join(f"{r}:{w:.1f}" for r, _, w in rows))
    far = ", ".join(f"> {t:g} cm {int((worst > t).sum())}" for t in FAR_CM)
    print(f"{overrides or 'defaults'}: ATE {rms.mean():.2f} cm (mean over robots), max error "
          f"mean {worst.mean():.2f} cm, worst {worst.max():.1f} cm; robots {far}")


if __name__ == "__main__":
    main()
