"""Edge planning update on a synthetic house-sized map with 3 robots; prints a markdown table.

The house is 16 m × 12 m with 2.5 m walls, six rooms joined by doorways and some furniture,
seen by 3 robots as 8 submaps each (each in its own rotated frame), covering the house but for
its east end, so frontiers and goals exist. Measured (medians of `--repeats`):
- full plan: a fresh planner's first plan (merge all submaps, grid, fields, frontiers, assign);
- incremental plan: one edge tick's worth of new data (a delta per robot) then plan;
- the stages of a plan on their own.

Run: .venv/bin/python bench/bench_edge.py [--repeats N]
"""

from __future__ import annotations

import argparse
import logging
import math
import statistics
import time
from collections.abc import Callable

import numpy as np

from schemas.messages import Pose2D, RobotPose, Submap
from services.common.geometry import T_from_xyyaw, invert, transform_points
from services.common.planning import inflate
from services.edge_server.config import EdgeConfig
from services.edge_server.frontiers import detect_frontiers
from services.edge_server.planner import EdgePlanner
from services.edge_server.robot_fields import all_fields as robot_fields
from services.edge_server.spatial_frontiers import detect_spatial_frontiers

V = 0.05
W_M, H_M, WALL_H = 16.0, 12.0, 2.5


def house_occupancy() -> np.ndarray:
    """(H, W) bool wall/furniture cells of the house at 5 cm."""
    H, W = int(H_M / V), int(W_M / V)
    occ = np.zeros((H, W), bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    for x in (5.0, 10.0):  # interior walls along y, with doorways
        c = int(x / V)
        occ[:, c] = True
        occ[int(2.5 / V) : int(3.5 / V), c] = False
        occ[int(8.5 / V) : int(9.5 / V), c] = False
    r = int(6.0 / V)  # a wall along x, with doorways
    occ[r, :] = True
    for x0 in (2.0, 7.0, 12.5):
        occ[r, int(x0 / V) : int((x0 + 1.0) / V)] = False
    for x0, y0 in ((1.5, 1.5), (7.0, 4.0), (12.0, 8.0), (3.0, 9.5)):  # furniture blocks
        occ[int(y0 / V) : int((y0 + 0.6) / V), int(x0 / V) : int((x0 + 1.2) / V)] = True
    return occ


def house_points(occ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World voxel centres of walls (full height) and floor, and the free floor xy."""
    rc = np.argwhere(occ)
    layers = np.arange(int(WALL_H / V))
    wall = np.column_stack([np.repeat(rc[:, 1], layers.size), np.repeat(rc[:, 0], layers.size),
                            np.tile(layers, len(rc))])
    free_rc = np.argwhere(~occ)
    floor = np.column_stack([free_rc[:, 1], free_rc[:, 0], np.zeros(len(free_rc), int)])
    points = (np.concatenate([wall, floor]) + 0.5) * V
    return points, (free_rc[:, ::-1] + 0.5) * V


def make_submaps(points: np.ndarray, free_xy: np.ndarray, rng: np.random.Generator) -> list[Submap]:
    """3 robots × 8 submaps tiling x ∈ [0, 13] m (the east end stays unknown)."""
    out, seq = [], {0: 0, 1: 0, 2: 0}
    strips = np.linspace(0.0, 13.0, 9)
    for j in range(8):
        for robot in range(3):
            y_lo, y_hi = robot * H_M / 3, (robot + 1) * H_M / 3
            T = T_from_xyyaw(strips[j] + 0.8, y_lo + 2.0, float(rng.uniform(-math.pi, math.pi)))
            sel = ((points[:, 0] >= strips[j]) & (points[:, 0] < strips[j + 1])
                   & (points[:, 1] >= y_lo) & (points[:, 1] < y_hi))
            fsel = ((free_xy[:, 0] >= strips[j]) & (free_xy[:, 0] < strips[j + 1])
                    & (free_xy[:, 1] >= y_lo) & (free_xy[:, 1] < y_hi))
            p_sub = transform_points(invert(T), points[sel])
            f_world = np.column_stack([free_xy[fsel], np.zeros(fsel.sum())])
            f_sub = transform_points(invert(T), f_world)
            out.append(Submap(
                robot_id=robot, submap_id=j, seq=seq[robot], tick=j + 1, stamp_ns=0,
                T_world_submap=T, points_mm=np.round(p_sub.T * 1000).astype(np.int16),
                colors=rng.integers(0, 255, (sel.sum(), 3), dtype=np.uint8),
                counts=np.ones(sel.sum(), np.uint16),
                free_cells=np.unique(np.floor(f_sub[:, :2] / V).astype(np.int16), axis=0).T.copy(),
                cell_m=V,
            ))
            seq[robot] += 1
    return out


def delta_for(sm: Submap, seq: int, tick: int, rng: np.random.Generator) -> Submap:
    """A small delta of submap `sm`: 600 new voxels (a camera tick's worth) in its frame."""
    pts = rng.uniform(-1.0, 1.0, (600, 3)) + [0.0, 0.0, 1.0]
    return sm.model_copy(update={
        "seq": seq, "tick": tick, "points_mm": np.round(pts.T * 1000).astype(np.int16),
        "colors": np.zeros((600, 3), np.uint8), "counts": np.ones(600, np.uint16),
        "free_cells": np.zeros((2, 0), np.int16),
    })


def loaded_planner(submaps: list[Submap]) -> EdgePlanner:
    planner = EdgePlanner(EdgeConfig(), tick_s=0.1)
    for sm in submaps:
        planner.on_submap(sm)
    for robot, (x, y) in enumerate(((2.5, 2.0), (7.5, 7.5), (11.5, 3.0))):
        planner.on_pose(RobotPose(robot_id=robot, tick=0, stamp_ns=0,
                                  pose_world=Pose2D(x=x, y=y, yaw=0.0)))
    return planner


def median_ms(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    rng = np.random.default_rng(0)
    points, free_xy = house_points(house_occupancy())
    submaps = make_submaps(points, free_xy, rng)
    rows: list[tuple[str, float]] = []

    rows.append(("full plan (fresh planner, 24 submaps)",
                 median_ms(lambda: loaded_planner(submaps).plan(10), args.repeats)))
    planner = loaded_planner(submaps)
    out = planner.plan(10)
    last = {sm.robot_id: sm for sm in submaps}
    state = {"tick": 20, "seq": 8}

    def incremental() -> None:
        for sm in last.values():
            planner.on_submap(delta_for(sm, state["seq"], state["tick"], rng))
        state["tick"] += 10
        state["seq"] += 1
        planner.plan(state["tick"])

    rows.append(("incremental plan (3 deltas of 600 voxels)", median_ms(incremental, args.repeats)))
    snap = planner.last_grid
    assert snap is not None
    cfg = planner.config
    traversable = snap.free & ~inflate(snap.occupied, math.ceil(cfg.robot_radius_m / V))
    starts = dict(zip([0, 1, 2], snap.spec.cell_of([[2.5, 2.0], [7.5, 7.5], [11.5, 3.0]]),
                      strict=True))
    fields = robot_fields(traversable, starts, cfg.start_snap_m / V)
    reach = np.logical_or.reduce([np.isfinite(f) for f in fields.values()])
    rows += [
        ("  merged grid", median_ms(lambda: planner.grid.update(planner.store, planner.merged),
                                    args.repeats)),
        ("  inflate", median_ms(lambda: inflate(snap.occupied, 4), args.repeats)),
        ("  distance fields (3 robots)",
         median_ms(lambda: robot_fields(traversable, starts, 20.0), args.repeats)),
        ("  2D grid frontiers + goals f′ (nearest/utility)",
         median_ms(lambda: detect_frontiers(snap.free, snap.known, reach, snap.spec, cfg),
                   args.repeats)),
        ("  3D F_u/F_w regions + gains + goals f′ (space)",
         median_ms(lambda: detect_spatial_frontiers(planner.merged, snap.known, reach, snap.spec,
                                                    cfg), args.repeats)),
        ("  map merger update (nothing new)",
         median_ms(lambda: planner.merger.update(planner.store), args.repeats)),
    ]
    print(f"\nmerged map: {len(planner.merged)} voxels; grid {snap.spec.height}×{snap.spec.width}"
          f" cells; {len(out.frontiers.frontiers)} frontiers; assigned {out.frontiers.assigned}\n")
    print("| stage | median ms |\n|---|---|")
    for name, ms in rows:
        print(f"| {name} | {ms:.1f} |")


if __name__ == "__main__":
    main()
