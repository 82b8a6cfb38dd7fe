"""Back-end replay: the agent's front end + keyframe pose graph on a finished mission's paths.

Like bench_localization.py (whose recording it reuses: frames rendered on the true paths,
teammates removed by segmentation, the simulator's odometry model), but each robot also keeps
keyframe submaps and runs the loop-closing back end. Reported per robot: every accepted loop
closure's error against the true relative pose, keyframe pose error (before and after the
back end), and the BV of the map the submaps make at their final poses, with the back end on
and off. Ground truth is read here only to score.

Run: .venv/bin/python bench/bench_back_end.py RUN_DIR [--loop search_radius_m=3 ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).parent))
from bench_localization import bv, load_or_record  # noqa: E402

from services.common import voxels  # noqa: E402
from services.common.geometry import (  # noqa: E402
    T_from_xyyaw,
    invert,
    transform_points,
    xyyaw_from_T,
)
from services.evaluator.evaluate import RunConfig, probe_for  # noqa: E402
from services.robot_agent.back_end import BackEnd  # noqa: E402
from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.local_map import KeyframeMapper  # noqa: E402
from services.robot_agent.localization import Localizer  # noqa: E402
from services.robot_agent.params import loop_params, registration_params  # noqa: E402
from services.robot_agent.projection import cam_to_base, depth_to_points  # noqa: E402
from services.simulator.core import odometry_noise  # noqa: E402
from services.simulator.odometry import WheelOdometry  # noqa: E402


def replay(rec, robot: int, cfg: AgentConfig, sim_cfg, loop: dict, back_end_on: bool):
    odom = WheelOdometry(tuple(rec.poses[robot, 0]), odometry_noise(sim_cfg, robot),
                         np.random.default_rng([sim_cfg.seed, 2, robot]))
    loc = Localizer(registration_params(cfg))
    mapper = KeyframeMapper(cfg)
    base = loop_params(cfg)
    reg = {k[4:]: v for k, v in loop.items() if k.startswith("reg.")}
    params = dataclasses.replace(
        base, registration=dataclasses.replace(base.registration, **reg),
        **{k: v for k, v in loop.items() if not k.startswith("reg.")})
    be = BackEnd(params, robot) if back_end_on else None
    frame_of = {int(k): f for f, k in enumerate(rec.frame_ticks)}
    truth: dict[int, np.ndarray] = {}
    for t, k in enumerate(rec.ticks):
        true = tuple(rec.poses[robot, t])
        o = odom.update(true, sim_cfg.tick_s)[0] if t > 0 else true
        f = frame_of.get(int(k))
        if f is None:
            continue
        depth, mates = rec.depth[robot, f].astype(np.float32), rec.teammate[robot, f]
        removed = float(np.count_nonzero(mates)) / max(np.count_nonzero(depth), 1)
        cam = depth_to_points(np.where(mates, 0.0, depth), rec.K, cfg.pixel_stride,
                              rec.range_m)
        points_base = cam_to_base(cam.points_cam, rec.T_base_cam[robot])
        T_loc_base = loc.update(points_base, T_from_xyyaw(*o), removed).T_loc_base
        if mapper.needs_keyframe(T_loc_base, int(k)):
            closed = mapper.current
            sub = mapper.start_keyframe(T_loc_base, int(k))
            truth[sub.submap_id] = T_from_xyyaw(*true)
            if be is not None:
                be.on_keyframe(closed, sub, mapper)
        T_sub_base = invert(mapper.current.T_odom_submap) @ T_loc_base
        mapper.integrate(transform_points(T_sub_base, points_base),
                         np.zeros((len(points_base), 3)), np.empty((0, 2)))
    return mapper, be, truth


def pose_errors(mapper: KeyframeMapper, truth: dict[int, np.ndarray]) -> np.ndarray:
    """(K, 2) keyframe position error m and yaw error deg at the final poses."""
    out = []
    for sub in mapper.submaps():
        dx, dy, dyaw = xyyaw_from_T(invert(truth[sub.submap_id]) @ sub.pose())
        out.append((np.hypot(dx, dy), abs(np.degrees(dyaw))))
    return np.array(out)


def team_map(mapper: KeyframeMapper, voxel_m: float) -> np.ndarray:
    pts = [transform_points(sub.pose(), voxels.centres(voxels.unpack(sub.keys), voxel_m))
           for sub in mapper.submaps() if len(sub)]
    return voxels.downsample(np.concatenate(pts), 0.05)[1]


def closure_errors(be: BackEnd, truth: dict[int, np.ndarray]) -> np.ndarray:
    """(C, 2) error of each accepted closure against the true relative pose (m, deg)."""
    out = []
    for c in be.graph.closures:
        T_true = invert(truth[c.a]) @ truth[c.b]
        dx, dy, dyaw = xyyaw_from_T(invert(T_true) @ c.T_a_b)
        out.append((np.hypot(dx, dy), abs(np.degrees(dyaw))))
    return np.array(out).reshape(-1, 2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--loop", nargs="*", default=[], help="LoopParams overrides, key=value")
    ap.add_argument("--set", nargs="*", default=[], help="AgentConfig overrides, key=value")
    ap.add_argument("--robots", type=int, nargs="*")
    ap.add_argument("--only-on", action="store_true", help="skip the back-end-off replay")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    loop = {k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.loop)}
    cfg = AgentConfig(**{k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.set)})
    run_cfg = RunConfig.read(args.run_dir / "config.yaml")
    rec = load_or_record(args.run_dir)
    probe = probe_for(run_cfg.sim)
    maps: dict[bool, list[np.ndarray]] = {False: [], True: []}
    print(f"loop overrides {loop}")
    for r in args.robots or range(rec.poses.shape[0]):
        for on in (True,) if args.only_on else (False, True):
            mapper, be, truth = replay(rec, r, cfg, run_cfg.sim, loop, on)
            err = pose_errors(mapper, truth)
            world = team_map(mapper, cfg.voxel_m)
            maps[on].append(world)
            line = (f"robot {r} back end {'on ' if on else 'off'}: keyframe error median "
                    f"{np.median(err[:, 0]) * 100:.1f} cm, max {err[:, 0].max() * 100:.1f} cm,"
                    f" yaw max {err[:, 1].max():.2f}°; BV {bv(probe, world):.4f} %")
            if be is not None:
                ce = closure_errors(be, truth)
                line += (f"; closures {be.graph.stats()}, error median "
                         f"{np.median(ce[:, 0]) * 100 if len(ce) else 0:.1f} cm / "
                         f"{np.median(ce[:, 1]) if len(ce) else 0:.2f}°, max "
                         f"{ce[:, 0].max() * 100 if len(ce) else 0:.1f} cm / "
                         f"{ce[:, 1].max() if len(ce) else 0:.2f}°")
            print(line, flush=True)
    for on in (True,) if args.only_on else (False, True):
        print(f"team map BV back end {'on' if on else 'off'}: "
              f"{bv(probe, np.concatenate(maps[on])):.4f} %")


if __name__ == "__main__":
    main()
