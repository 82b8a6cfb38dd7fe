"""Robot agent per-frame cost at 160×120 on synthetic frames, and its submap traffic.

Run: .venv/bin/python bench/bench_agent.py [--frames N]
Prints a markdown table of median (and p90) milliseconds per stage and kB per sim second.
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from schemas import encode  # noqa: E402
from schemas.messages import Goal, Odometry, Pose2D, RgbdFrame  # noqa: E402
from services.common.geometry import (  # noqa: E402
    T_from_xyyaw,
    invert,
    transform_points,
    transform_xy,  # noqa: E402
)
from services.robot_agent.agent import AgentCore  # noqa: E402
from services.robot_agent.config import AgentConfig  # noqa: E402
from services.robot_agent.local_grid import floor_rays  # noqa: E402
from services.robot_agent.projection import (  # noqa: E402
    T_base_cam_forward,
    cam_to_base,
    depth_to_points,
    intrinsics,
    pixel_colors,
)
from services.robot_agent.synthetic import BoxWorld, T_world_cam_of, render  # noqa: E402

W, H, TICK_S, CAMERA_EVERY = 160, 120, 0.1, 2
WORLD = (
    BoxWorld.room(-5.0, 5.0, -4.0, 4.0)
    .with_box((-1.0, -0.6, -4.0, 1.0, 0.0, 1.0))
    .with_box((2.0, 2.6, 0.5, 1.2, 0.0, 0.5))
    .with_box((-3.5, -3.0, 2.0, 2.4, 0.0, 0.8))
)


def trajectory(ticks: int) -> list[tuple[float, float, float]]:
    """An ellipse at ~0.4 m/s around the room's middle."""
    out = []
    for k in range(ticks):
        a = 0.4 * k * TICK_S / 3.5
        out.append((3.5 * math.cos(a), 2.7 * math.sin(a), a + math.pi / 2))
    return out


def frames(poses: list[tuple[float, float, float]]) -> list[RgbdFrame]:
    K, T_base_cam = intrinsics(W, H, math.radians(84.1)), T_base_cam_forward(0.35)
    out = []
    for k, pose in enumerate(poses):
        depth, rgb = render(WORLD, K, (H, W), T_world_cam_of(*pose, T_base_cam), 5.0)
        out.append(RgbdFrame(robot_id=0, tick=k, stamp_ns=k * 10**8, depth_m=depth, rgb=rgb,
                             K=K, T_base_cam=T_base_cam, range_max_m=5.0))
    return out


def stage_times(core: AgentCore, frame: RgbdFrame, pose: tuple[float, float, float]) -> dict:
    """The stages of AgentCore._integrate, timed one by one (same calls, same order)."""
    cfg = core.config
    t = {}
    t0 = time.perf_counter()
    cam = depth_to_points(frame.depth_m, frame.K, cfg.pixel_stride, frame.range_max_m)
    points_base = cam_to_base(cam.points_cam, frame.T_base_cam)
    t["projection"] = time.perf_counter() - t0
    T_odom_base = T_from_xyyaw(*pose)
    t0 = time.perf_counter()
    if core.mapper.needs_keyframe(T_odom_base, frame.tick):
        core.mapper.take_delta()
        core.mapper.start_keyframe(T_odom_base, frame.tick)
    T_submap_base = invert(core.mapper.current.T_odom_submap) @ T_odom_base
    core.mapper.current.add_points(
        transform_points(T_submap_base, points_base), pixel_colors(frame.rgb, cam), cfg.voxel_m
    )
    t["submap voxels"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    free_base = floor_rays(points_base, frame.T_base_cam[:2, 3], cfg.obstacle_z_min_m,
                           cfg.obstacle_z_max_m, cfg.cell_m, cfg.ray_bin_rad)
    floor = points_base[:, 2] <= cfg.obstacle_z_min_m
    core.mapper.current.add_free(transform_xy(T_submap_base, free_base), cfg.cell_m)
    band = ~floor & (points_base[:, 2] <= cfg.obstacle_z_max_m)
    core.grid.update(transform_xy(T_odom_base, free_base),
                     transform_xy(T_odom_base, points_base[band, :2]))
    t["free rays + grid"] = time.perf_counter() - t0
    return t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=120)
    args = parser.parse_args()
    ticks = args.frames * CAMERA_EVERY
    poses = trajectory(ticks)
    rgbd = frames(poses)

    # 1. stages, on a core whose grid exists (first odometry creates it)
    core = AgentCore(AgentConfig(), 0, TICK_S)
    core.on_odometry(Odometry(robot_id=0, tick=0, stamp_ns=0, pose_odom=Pose2D(x=0, y=0, yaw=0),
                              v_mps=0, omega_radps=0))
    stages: dict[str, list[float]] = {}
    for k in range(0, ticks, CAMERA_EVERY):
        for name, s in stage_times(core, rgbd[k], poses[k]).items():
            stages.setdefault(name, []).append(s)
    # planning: a fresh A* across the mapped room each time
    plan = []
    for gx, gy in [(-4.0, -3.0), (4.0, 3.0), (-4.0, 3.0), (4.0, -3.0)] * 5:
        core.nav.set_goal(Goal(robot_id=0, tick=0, goal_id=len(plan) + 1, x=gx, y=gy,
                               frontier_class="unexplored", revenue=1.0), 0)
        t0 = time.perf_counter()
        core.nav._plan(core.grid, tuple(poses[-1][:3]), 0)
        plan.append(time.perf_counter() - t0)
    stages["planning (A* incl. inflation, per replan)"] = plan

    # 2. the whole tick handler, camera ticks, plus submap traffic
    core = AgentCore(AgentConfig(), 0, TICK_S)
    camera_ticks, other_ticks, submap_bytes = [], [], 0
    for k in range(ticks):
        if k % CAMERA_EVERY == 0:
            core.on_rgbd(rgbd[k])
        x, y, yaw = poses[k]
        odom = Odometry(robot_id=0, tick=k, stamp_ns=k * 10**8,
                        pose_odom=Pose2D(x=x, y=y, yaw=yaw), v_mps=0.4, omega_radps=0.0)
        t0 = time.perf_counter()
        outs = core.on_odometry(odom)
        (camera_ticks if k % CAMERA_EVERY == 0 else other_ticks).append(time.perf_counter() - t0)
        submap_bytes += sum(len(encode(o.message)) for o in outs if o.topic == "submap")
    stages["whole camera tick (AgentCore.on_odometry, idle)"] = camera_ticks
    stages["whole non-camera tick"] = other_ticks

    print(f"Robot agent, {W}×{H}, {args.frames} synthetic frames, {ticks * TICK_S:.0f} sim s\n")
    print("| stage | median ms | p90 ms |")
    print("|---|---:|---:|")
    for name, s in stages.items():
        print(f"| {name} | {1e3 * np.median(s):.2f} | {1e3 * np.percentile(s, 90):.2f} |")
    print(f"\nsubmap traffic: {submap_bytes / 1e3 / (ticks * TICK_S):.1f} kB per sim second "
          f"({core.outbox.seq} messages, {core.mapper.next_id} submaps)")


if __name__ == "__main__":
    main()
