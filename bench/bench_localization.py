"""Localization replay: the agent's frame-to-map registration on a finished mission's paths.

Every robot is placed on its recorded ground-truth pose tick by tick, its camera frame is
rendered, teammate pixels are removed with the simulator's segmentation (a perfect DRF, so
that only localization is measured; frames they hide too much of are skipped as in the
agent), and the simulator's odometry model drifts the recorded
motion exactly as in the mission. Each robot then runs the agent's `Localizer`. Reported:
pose error over time, accepted registrations, and the bounding volume (the evaluator's ghost
metric) of the 5 cm voxel map each robot builds from its estimated poses, against the same
map built from the true poses. Rendered frames are cached next to the run, so parameter
sweeps replay in about a minute.

Run: .venv/bin/python bench/bench_localization.py RUN_DIR... [--set reg_fusion=gate ...]
[--filter r_m=0.01 ...] [--odom-draws N]; with several replays a summary line closes the output.
(RUN_DIR from e.g. `spacemap run --robots 3 --sim-time 300 --out RUN_DIR`).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402

from services.common import voxels  # noqa: E402
from services.common.geometry import T_from_xyyaw, transform_points, xyyaw_from_T  # noqa: E402
from services.evaluator import run_files as rf  # noqa: E402
from services.evaluator.evaluate import RunConfig, probe_for  # noqa: E402
from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.drift_filter import FilterParams  # noqa: E402
from services.robot_agent.localization import Localizer  # noqa: E402
from services.robot_agent.params import registration_params  # noqa: E402
from services.robot_agent.projection import cam_to_base, depth_to_points  # noqa: E402
from services.simulator.core import Simulation, odometry_noise  # noqa: E402
from services.simulator.odometry import WheelOdometry  # noqa: E402

log = logging.getLogger("bench_localization")
VOXEL_M = 0.05
FAIL_M = 0.08  # a pose this far off maps walls into ghosts (> 0.10 m with 5 cm voxels)


@dataclass
class Recording:
    """Camera frames of every robot on the recorded paths (teammate pixels zeroed)."""

    ticks: np.ndarray  # (T,) every tick of the run
    poses: np.ndarray  # (R, T, 3) true x, y, yaw per tick
    frame_ticks: np.ndarray  # (F,) ticks with a camera frame
    depth: np.ndarray  # (R, F, H, W) float32 metres, 0 = none
    teammate: np.ndarray  # (R, F, H, W) bool: a robot's pixel (from the segmentation)
    K: np.ndarray
    T_base_cam: np.ndarray  # (R, 4, 4)
    range_m: float


def place(sim: Simulation, poses: np.ndarray) -> None:
    """Put every robot on its (x, y, yaw); slide and hinge qpos are relative to the spawn."""
    m = sim.model
    for i, robot in enumerate(sim.robots):
        for axis, act in enumerate(robot.actuators):
            joint = m.actuator_trnid[act, 0]
            sim.data.qpos[m.jnt_qposadr[joint]] = poses[i, axis] - sim.spawns[i][axis]
    mujoco.mj_forward(m, sim.data)


def record(run_dir: Path) -> Recording:
    config = RunConfig.read(run_dir / "config.yaml")
    sim = Simulation(config.sim)
    tracks = [rf.read_tum(rf.gt_trajectory_path(run_dir, r)) for r in range(sim.n_robots)]
    n = min(len(s) for s, _ in tracks)
    poses = np.stack([xyyaw[:n] for _, xyyaw in tracks])
    ticks = np.round(tracks[0][0][:n] / config.sim.tick_s).astype(int)
    frame_ticks = ticks[ticks % config.sim.camera_every_ticks == 0]
    robot_geoms = np.array(sorted({g for r in sim.robots for g in r.geoms}))
    depth = []
    for t, k in enumerate(ticks):
        if k % config.sim.camera_every_ticks:
            continue
        place(sim, poses[:, t])
        row = []
        for i in range(sim.n_robots):
            img = sim.render(i, segmentation=True)
            row.append((img.depth_m,
                        np.isin(img.segmentation, robot_geoms) & (img.depth_m > 0)))
        depth.append(row)
    rec = Recording(ticks, poses, frame_ticks,
                    np.array([[d for d, _ in row] for row in depth]).transpose(1, 0, 2, 3),
                    np.array([[m for _, m in row] for row in depth]).transpose(1, 0, 2, 3),
                    sim.K, np.stack([sim.T_base_cam(i) for i in range(sim.n_robots)]),
                    config.sim.range_m)
    sim.close()
    return rec


def load_or_record(run_dir: Path) -> Recording:
    cache = run_dir / "localization_frames.npz"
    if cache.exists():
        z = np.load(cache)
        return Recording(z["ticks"], z["poses"], z["frame_ticks"], z["depth"], z["teammate"],
                         z["K"], z["T_base_cam"], float(z["range_m"]))
    t0 = time.perf_counter()
    rec = record(run_dir)
    partial = cache.with_suffix(f".{os.getpid()}.npz")  # replays in parallel share the cache
    np.savez(partial, **{k: getattr(rec, k) for k in Recording.__dataclass_fields__})
    partial.replace(cache)
    log.info("rendered %d frames per robot in %.0f s", len(rec.frame_ticks),
             time.perf_counter() - t0)
    return rec


def replay(rec: Recording, robot: int, cfg: AgentConfig, sim_cfg, poses_true: bool = False,
           reg: dict | None = None, odom_draw: int = 0):
    """(per-frame xy error m, yaw error rad, accepted, ms per frame, world voxel map).

    `odom_draw` 0 drifts the odometry as in the mission; k > 0 is the k-th other random draw
    of the same noise model (more trials from one rendered run)."""
    noise = odometry_noise(sim_cfg, robot)
    spawn = tuple(rec.poses[robot, 0])
    seed = [sim_cfg.seed, 2, robot] + ([odom_draw] if odom_draw else [])
    odom = WheelOdometry(spawn, noise, np.random.default_rng(seed))
    loc = Localizer(dataclasses.replace(registration_params(cfg), **(reg or {})))
    frame_of = {int(k): f for f, k in enumerate(rec.frame_ticks)}
    err_xy, err_yaw, accepted, ms, cloud = [], [], [], [], []
    for t, k in enumerate(rec.ticks):
        true = tuple(rec.poses[robot, t])
        o = odom.update(true, sim_cfg.tick_s)[0] if t > 0 else spawn
        f = frame_of.get(int(k))
        if f is None:
            continue
        depth, mates = rec.depth[robot, f].astype(np.float32), rec.teammate[robot, f]
        removed = float(np.count_nonzero(mates)) / max(np.count_nonzero(depth), 1)
        cam = depth_to_points(np.where(mates, 0.0, depth), rec.K, cfg.pixel_stride,
                              rec.range_m)
        points_base = cam_to_base(cam.points_cam, rec.T_base_cam[robot])
        t0 = time.perf_counter()
        outcome = loc.update(points_base, T_from_xyyaw(*o), removed)
        ms.append((time.perf_counter() - t0) * 1e3)
        T_est = T_from_xyyaw(*true) if poses_true else outcome.T_loc_base
        x, y, yaw = xyyaw_from_T(T_est)
        err_xy.append(np.hypot(x - true[0], y - true[1]))
        err_yaw.append(abs(np.angle(np.exp(1j * (yaw - true[2])))))
        accepted.append(outcome.accepted)
        cloud.append(voxels.downsample(transform_points(T_est, points_base), VOXEL_M)[1]
                     if len(points_base) else np.empty((0, 3)))
    world = voxels.downsample(np.concatenate(cloud), VOXEL_M)[1]
    return np.array(err_xy), np.array(err_yaw), np.array(accepted), np.array(ms), world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dirs", type=Path, nargs="+", help="finished mission folders")
    ap.add_argument("--set", nargs="*", default=[], help="AgentConfig overrides, key=value")
    ap.add_argument("--reg", nargs="*", default=[], help="RegistrationParams overrides")
    ap.add_argument("--filter", nargs="*", default=None,
                    help="fuse by the drift filter (drift_filter.FilterParams overrides)")
    ap.add_argument("--robots", type=int, nargs="*", help="only these robots")
    ap.add_argument("--truth", action="store_true", help="also build maps from the true poses")
    ap.add_argument("--odom-draws", type=int, default=1,
                    help="replay each run with this many odometry noise draws (the mission's "
                    "first)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    overrides = {k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.set)}
    reg = {k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.reg)}
    if args.filter is not None:
        reg["filter"] = FilterParams(
            **{k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.filter)})

    cfg = AgentConfig(**overrides)
    print(f"overrides {overrides} {reg}")
    team_bv, max_err = [], []
    for run_dir in args.run_dirs:
        for draw in range(args.odom_draws):
            print(f"== {run_dir}" + (f" odometry draw {draw}" if draw else ""))
            bv_run, errs = replay_run(run_dir, cfg, reg, args.robots, args.truth, draw)
            team_bv.append(bv_run)
            max_err += errs
    if len(team_bv) > 1:
        over = sum(e > FAIL_M for e in max_err)
        print(f"summary over {len(team_bv)} replays: team map BV median "
              f"{np.median(team_bv):.4f} %, mean {np.mean(team_bv):.4f} %, worst "
              f"{max(team_bv):.4f} %; robots whose error passed {FAIL_M * 100:.0f} cm: "
              f"{over} of {len(max_err)}")


def replay_run(run_dir: Path, cfg: AgentConfig, reg: dict, robots: list[int] | None,
               truth: bool, odom_draw: int = 0) -> tuple[float, list[float]]:
    """(team map BV %, each robot's largest xy error m) of one run's replay; prints a line per
    robot."""
    run_cfg = RunConfig.read(run_dir / "config.yaml")
    rec = load_or_record(run_dir)
    probe = probe_for(run_cfg.sim)
    maps, truth_maps, max_err = [], [], []
    for r in robots or range(rec.poses.shape[0]):
        exy, eyaw, acc, ms, world = replay(rec, r, cfg, run_cfg.sim, reg=reg,
                                          odom_draw=odom_draw)
        maps.append(world)
        max_err.append(float(exy.max()))
        bins = np.array_split(np.arange(len(exy)), 6)
        trend = " ".join(f"{exy[b].max() * 100:4.1f}/{np.degrees(eyaw[b].max()):.1f}°"
                         for b in bins)
        print(f"robot {r}: xy err median {np.median(exy) * 100:.1f} cm, max "
              f"{exy.max() * 100:.1f} cm; yaw max {np.degrees(eyaw.max()):.2f}°; accepted "
              f"{acc.mean() * 100:.0f} %; {np.median(ms):.1f} ms/frame; per sixth (cm/°): "
              f"{trend}; BV {bv(probe, world):.4f} %")
        if truth:
            truth_maps.append(replay(rec, r, cfg, run_cfg.sim, poses_true=True)[4])
    team = bv(probe, np.concatenate(maps))
    print(f"team map BV {team:.4f} %")
    if truth:
        print(f"team map BV with true poses {bv(probe, np.concatenate(truth_maps)):.4f} %")
    return team, max_err


def bv(probe, points_world: np.ndarray) -> float:
    pts = voxels.downsample(points_world, VOXEL_M)[1]
    _, ghosts, occupied = probe.ghost_point_mask(pts, probe.surface_distance(pts))
    return 100.0 * ghosts / max(occupied, 1)


if __name__ == "__main__":
    main()
