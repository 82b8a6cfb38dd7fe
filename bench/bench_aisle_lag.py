"""How far frame-to-map registration lags along a featureless aisle, and which points cause it.

A synthetic aisle (`synthetic.aisle_points`: two rack faces with uprights every 2.7 m) seen by
a 5 m, 84° camera with the simulator's depth noise. The robot drives 6 m in 10 cm steps on
perfect odometry; each frame is registered against the agent's registration voxel map
(`FrameRegistrar`) from the odometry guess and joins the map at the pose found, so a bias per
registration adds up along the chain (docs/agent.md, "Along the aisles"). Variants align only
the points within a range (`agent.reg_align_max_range_m`) and/or a bearing margin inside the
field of view (the frame always joins the map whole), or keep, aligned and mapped, only the
points whose downsampling cell or registration-map voxel the view holds whole
(`agent.reg_whole_voxels`). Printed: the chain's final along-track
error per seed (negative: it lags), and the median.

    .venv/bin/python bench/bench_aisle_lag.py --seeds 10
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from services.common.geometry import T_from_xyyaw, xyyaw_from_T  # noqa: E402
from services.robot_agent.registrar import FrameRegistrar, RegistrationParams  # noqa: E402
from services.robot_agent.synthetic import aisle_frame, aisle_points  # noqa: E402
from services.robot_agent.view_voxels import corners_inside, whole_voxel_mask  # noqa: E402

HALF_FOV_DEG = 42.0
RANGE_M = 5.0  # synthetic.aisle_frame's camera range
STEP_M, DRIVE_M = 0.1, 6.0
CELL_M = 0.08  # the registrar's downsampling cell (RegistrationParams.downsample_m)
# (align range m or 0 for all, bearing margin deg inside the field of view or 0 for none,
# which points a frame keeps, aligned and inserted: "" all, "cells" those in downsampling
# cells (base frame) wholly inside the view, "voxels" those in registration-map voxels (loc
# frame, the agent's `reg_whole_voxels`) wholly inside it)
VARIANTS = [(0.0, 0.0, ""), (4.0, 0.0, ""), (0.0, 8.0, ""), (4.0, 8.0, ""),
            (3.5, 10.0, ""), (0.0, 0.0, "cells"), (0.0, 0.0, "voxels")]
WHAT = {"": "", "cells": "whole downsampling cells only (aligned and mapped)",
        "voxels": "whole map voxels only (aligned and mapped)"}
_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)


def in_view(points_base: np.ndarray) -> np.ndarray:
    """(N,) whether base-frame points lie in `synthetic.aisle_frame`'s view."""
    return ((points_base[:, 0] > 0.3) & (np.hypot(points_base[:, 0], points_base[:, 1]) < RANGE_M)
            & (np.abs(np.arctan2(points_base[:, 1], points_base[:, 0]))
               < np.radians(HALF_FOV_DEG)))


def in_whole_cells(points: np.ndarray, cell_m: float = CELL_M) -> np.ndarray:
    """(N,) whether each point's cell (base frame) lies wholly inside the camera's range and
    horizontal field of view: a cell the view cuts holds only its near part, and its mean
    sits back toward the robot."""
    idx = np.floor(points / cell_m).astype(np.int64)
    cells, inverse = np.unique(idx, axis=0, return_inverse=True)
    corners = (cells[:, None, :] + _CORNERS[None]) * cell_m
    inside = ((np.hypot(corners[..., 0], corners[..., 1]) < RANGE_M)
              & (np.degrees(np.abs(np.arctan2(corners[..., 1], corners[..., 0]))) < HALF_FOV_DEG)
              & (corners[..., 0] > 0.3)).all(axis=1)
    return inside[inverse.ravel()]


def chain_lag_m(seed: int, voxel_m: float, range_m: float, margin_deg: float,
                whole: str = "", noise_per_m2: float = 0.0005) -> float:
    """Final along-track error of the registered chain (m; < 0: behind the truth)."""
    world = aisle_points(np.random.default_rng(0))
    rng = np.random.default_rng(seed)
    reg = FrameRegistrar(RegistrationParams(map_voxel_m=voxel_m))
    xs = np.arange(0.0, DRIVE_M + 1e-9, STEP_M)
    est = 0.0
    for i, x in enumerate(xs):
        points = aisle_frame(world, x, rng, noise_per_m2=noise_per_m2,
                             half_fov_rad=np.radians(HALF_FOV_DEG))
        if whole == "cells":
            points = points[in_whole_cells(points)]
        elif whole == "voxels":  # at the odometry guess, as the agent does
            guess = T_from_xyyaw(est + STEP_M if i else 0.0, 0.0, 0.0)
            points = points[whole_voxel_mask(points, guess, voxel_m, corners_inside(in_view))]
        if i:
            keep = np.ones(len(points), bool)
            if range_m > 0:
                keep &= np.hypot(points[:, 0], points[:, 1]) <= range_m
            if margin_deg > 0:
                bearing = np.degrees(np.abs(np.arctan2(points[:, 1], points[:, 0])))
                keep &= bearing < HALF_FOV_DEG - margin_deg
            tree = reg.cloud_tree(points[keep])
            aligned = "too few points" if tree is None else reg.align(
                tree[0], T_from_xyyaw(est + STEP_M, 0.0, 0.0))
            # a frame the map cannot hold keeps the odometry guess, as the agent's would
            est = est + STEP_M if isinstance(aligned, str) else xyyaw_from_T(aligned[0])[0]
        reg.insert(reg.cloud_tree(points)[0], T_from_xyyaw(est, 0.0, 0.0))
    return est - xs[-1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10, help="depth-noise seeds 1..N")
    ap.add_argument("--voxel", type=float, action="append", default=None,
                    help="registration map voxel size m (repeatable; default 0.05, the agent's)")
    ap.add_argument("--noise", type=float, default=0.0005,
                    help="depth noise σ per m² of range (the simulator's realistic default)")
    args = ap.parse_args()
    print(f"depth noise σ = {args.noise:g}·d²\n")
    print("| map voxel m | aligned points | lag cm per seed | median cm | % of 6 m |")
    print("|---:|---|---|---:|---:|")
    for voxel in args.voxel or [0.05]:
        for range_m, margin, whole in VARIANTS:
            lags = [100 * chain_lag_m(s, voxel, range_m, margin, whole, args.noise)
                    for s in range(1, args.seeds + 1)]
            what = ", ".join(filter(None, [f"within {range_m:g} m" if range_m else "",
                                           f"{margin:g}° inside the view's edges" if margin
                                           else "", WHAT[whole]])) or "all"
            med = statistics.median(lags)
            print(f"| {voxel:g} | {what} | {' / '.join(f'{v:+.2f}' for v in lags)} | "
                  f"{med:+.2f} | {med / DRIVE_M:+.2f} |", flush=True)


if __name__ == "__main__":
    main()
