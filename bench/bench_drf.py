"""DRF, localization drift and map traffic of the agent on a scripted MuJoCo scene.

Three robots in the house's living room cross each other's view: robot 1 shuttles north-south
and robot 2 east-west in front of robot 0, which sweeps its camera left and right. Each robot
runs its own `AgentCore` on the simulator's frames and odometry (teammate poses are the other
agents' own estimates of the previous tick, as on the bus). Against the simulator's
segmentation (bench only; agents never see it) the bench reports:

- teammate pixels removed and static pixels kept by the DRF, for a sweep of c and of the
  awareness test (the paper's inequality vs the partial-view variant), replayed on the recorded
  frames with the estimates of the run with registration and of the run without it;
- DRF time per frame (awareness + filter) at the camera resolution;
- localization drift (estimate vs truth) with and without frame-to-map registration;
- submap bytes per robot per sim second.

Run: .venv/bin/python bench/bench_drf.py [--ticks 600] [--out docs/bench_drf.md]
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import time
from dataclasses import dataclass

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from schemas import encode  # noqa: E402
from schemas.messages import Odometry, Pose2D, RgbdFrame, RobotPose, Submap  # noqa: E402
from services.robot_agent.agent import AgentCore  # noqa: E402
from services.robot_agent.awareness import in_view_partial, visible_paper  # noqa: E402
from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.drf import filter_mask  # noqa: E402
from services.robot_agent.params import drf_params  # noqa: E402
from services.robot_agent.projection import hfov_of  # noqa: E402
from services.simulator.config import SimConfig  # noqa: E402
from services.simulator.core import Simulation  # noqa: E402

log = logging.getLogger("bench_drf")
SPAWNS = [(6.0, 2.5, 0.0), (8.0, 1.0, math.pi / 2), (10.0, 4.0, math.pi)]
TURN_TICKS = 40  # π at π/4 rad/s and 0.1 s ticks


def shuttle(k: int, v: float, leg_ticks: int) -> tuple[float, float]:
    """Drive `leg_ticks` straight, turn around in place, repeat."""
    return (v, 0.0) if k % (leg_ticks + TURN_TICKS) < leg_ticks else (0.0, math.pi / 4)


def commands(k: int) -> dict[int, tuple[float, float]]:
    sweep = 0.25 * math.copysign(1.0, math.sin(2 * math.pi * k / 120))
    return {0: (0.0, sweep), 1: shuttle(k, 0.3, 80), 2: shuttle(k, 0.3, 80)}


@dataclass
class FrameRecord:
    robot: int
    depth: np.ndarray
    K: np.ndarray
    T_base_cam: np.ndarray
    range_m: float
    teammate: np.ndarray  # (H, W) bool, from the segmentation
    static: np.ndarray
    pose_est: tuple[float, float, float]
    mates_est: np.ndarray  # (N, 2) teammates' own estimates


@dataclass
class RunResult:
    frames: list[FrameRecord]
    drift_final_m: list[float]
    drift_max_m: list[float]
    kb_per_s: list[float]
    agent_ms: list[float]


def run_scene(ticks: int, agent_cfg: AgentConfig, record: bool) -> RunResult:
    """Run the scripted scene once with one AgentCore per robot."""
    cfg = SimConfig(world="house", robots=3, spawn=SPAWNS, seed=0)
    sim = Simulation(cfg)
    cores = [AgentCore(agent_cfg, i, cfg.tick_s, team_size=2) for i in range(3)]
    robot_geoms = [np.array(r.geoms) for r in sim.robots]
    est = [s for s in SPAWNS]
    frames: list[FrameRecord] = []
    drift_max, sub_bytes, agent_s = [0.0] * 3, [0] * 3, []
    for k in range(ticks):
        camera = k % cfg.camera_every_ticks == 0
        prev_est = list(est)
        for i, core in enumerate(cores):
            for j in range(3):
                if j != i and k > 0:  # as in missions: poses of tick k − 1 (node.TICKED)
                    x, y, yaw = prev_est[j]
                    core.on_pose(RobotPose(robot_id=j, tick=k - 1, stamp_ns=0,
                                           pose_world=Pose2D(x=x, y=y, yaw=yaw)))
            if camera:
                img = sim.render(i, segmentation=True)
                frame = RgbdFrame(robot_id=i, tick=k, stamp_ns=sim.stamp_ns, depth_m=img.depth_m,
                                  rgb=img.rgb, K=sim.K, T_base_cam=sim.T_base_cam(i),
                                  range_max_m=cfg.range_m)
                core.on_rgbd(frame)
            o = sim.odometry(i)
            t0 = time.perf_counter()
            outs = core.on_odometry(Odometry(
                robot_id=i, tick=k, stamp_ns=sim.stamp_ns,
                pose_odom=Pose2D(x=o.pose[0], y=o.pose[1], yaw=o.pose[2]), v_mps=o.v_mps,
                omega_radps=o.omega_radps))
            if camera:
                agent_s.append(time.perf_counter() - t0)
            pose = next(m.message.pose_world for m in outs if m.topic == "pose")
            est[i] = (pose.x, pose.y, pose.yaw)
            sub_bytes[i] += sum(len(encode(m.message)) for m in outs
                                if isinstance(m.message, Submap))
            tx, ty, _ = sim.true_pose(i)
            drift_max[i] = max(drift_max[i], math.hypot(pose.x - tx, pose.y - ty))
            if camera and record:
                mates = np.concatenate([robot_geoms[j] for j in range(3) if j != i])
                valid = (img.depth_m > 0) & (img.depth_m <= cfg.range_m)
                own_or_mate = np.isin(img.segmentation, np.concatenate(robot_geoms))
                frames.append(FrameRecord(
                    i, img.depth_m, sim.K, sim.T_base_cam(i), cfg.range_m,
                    valid & np.isin(img.segmentation, mates), valid & ~own_or_mate,
                    prev_est[i], np.array([prev_est[j][:2] for j in range(3) if j != i])))
        sim.step(commands(k))
    final = [math.hypot(est[i][0] - sim.true_pose(i)[0], est[i][1] - sim.true_pose(i)[1])
             for i in range(3)]
    sim_s = ticks * cfg.tick_s
    sim.close()
    return RunResult(frames, final, drift_max, [b / 1000.0 / sim_s for b in sub_bytes],
                     [s * 1e3 for s in agent_s])


@dataclass
class DrfScore:
    removed_pct: float
    kept_pct: float
    ms_median: float
    ms_p99: float
    teammate_px: int


def score_drf(frames: list[FrameRecord], cfg: AgentConfig) -> DrfScore:
    """Replay awareness + DRF on recorded frames with `cfg`'s c and awareness test."""
    params = drf_params(cfg)
    test = visible_paper if cfg.awareness == "paper" else in_view_partial
    removed = mate = kept = static = 0
    times = []
    for f in frames:
        t0 = time.perf_counter()
        seen = test(f.pose_est, f.mates_est, radius_m=cfg.robot_size_m,
                    fov_rad=hfov_of(f.K, f.depth.shape[1]), range_m=f.range_m, c=cfg.drf_c)
        mask = np.zeros(f.depth.shape, bool)
        if seen.any():
            mask = filter_mask(f.depth, f.K, f.T_base_cam, f.pose_est, f.mates_est[seen], params)
        times.append(time.perf_counter() - t0)
        removed += int((mask & f.teammate).sum())
        mate += int(f.teammate.sum())
        kept += int((~mask & f.static).sum())
        static += int(f.static.sum())
    t = np.array(times) * 1e3
    return DrfScore(100.0 * removed / max(mate, 1), 100.0 * kept / max(static, 1),
                    float(np.median(t)), float(np.percentile(t, 99)), mate)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=600)
    ap.add_argument("--out", default="")
    ap.add_argument("--c", type=float, nargs="*", default=[0.0, 0.1, 0.2, 0.25, 0.3, 0.4, 0.6])
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    base = AgentConfig()
    t0 = time.perf_counter()
    reg = run_scene(args.ticks, base, record=True)
    noreg = run_scene(args.ticks, base.model_copy(update={"registration": False}), record=True)
    nodrf = run_scene(args.ticks, base.model_copy(update={"drf": False}), record=False)
    log.info("scenes ran in %.0f s", time.perf_counter() - t0)
    lines = [f"Scene: {args.ticks} ticks ({args.ticks / 10:.0f} s sim), 3 robots, 160×120, "
             f"{len(reg.frames)} frames, {sum(f.teammate.sum() > 0 for f in reg.frames)} with a "
             "teammate in view.", "",
             "| estimates | awareness | c | teammate px removed % | static px kept % | "
             "DRF ms median | DRF ms p99 |", "|---|---|---|---|---|---|---|"]
    for name, run in (("registered", reg), ("odometry only", noreg)):
        for mode in ("paper", "partial"):
            for c in args.c:
                cfg = base.model_copy(update={"drf_c": c, "awareness": mode})
                s = score_drf(run.frames, cfg)
                lines.append(f"| {name} | {mode} | {c:.2f} | {s.removed_pct:.2f} | "
                             f"{s.kept_pct:.3f} | {s.ms_median:.2f} | {s.ms_p99:.2f} |")
    lines += ["", "| run | drift final m (per robot) | drift max m (per robot) | "
              "submap kB/s per robot | agent ms per camera tick (median / p90) |",
              "|---|---|---|---|---|"]
    for name, run in (("registration on", reg), ("registration off", noreg),
                      ("no DRF (registration on)", nodrf)):
        lines.append(
            f"| {name} | {', '.join(f'{d:.3f}' for d in run.drift_final_m)} | "
            f"{', '.join(f'{d:.3f}' for d in run.drift_max_m)} | "
            f"{', '.join(f'{b:.1f}' for b in run.kb_per_s)} | "
            f"{np.median(run.agent_ms):.1f} / {np.percentile(run.agent_ms, 90):.1f} |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text + "\n")


if __name__ == "__main__":
    main()
