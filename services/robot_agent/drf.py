"""Dynamic Robot Filter (paper §III-B): drop a teammate's pixels from a depth frame.

For each teammate that mutual awareness puts in view:

1. its position in the observer's frame at the camera height h_o (`target_in_base`), projected
   to (u, v, d) with K and the extrinsics T_base_cam (`project_target`);
2. a 3D box around it of size c/d. The paper leaves the unit open; here c/d is an *angle*, the
   same buffer as in mutual awareness, which at range d spans c metres. So the box is the robot's
   circle (radius R) grown by c metres across and along the line of sight, from the floor to the
   robot's top: c is the pose-estimate error (of both robots) the box tolerates;
3. DBSCAN (Open3D) on the box's points, voxelized at `voxel_m` first so the cost is bounded;
4. the clusters that are the robot are removed: every cluster with a point within R + c of the
   expected position whose horizontal extent fits the robot (diagonal ≤ 2R + 2 voxels). "Every"
   because a TurtleBot seen from the front is two clusters (chassis face, mast 0.14 m behind);
   the size test keeps walls and furniture that reach into the box.
5. spacemap's addition: every box point within the robot's footprint (half-diagonal) grown by the
   pose uncertainty `margin_m` of the expected position is removed too, whatever DBSCAN made of
   it. In missions a teammate touching a wall or furniture (one cluster too big for the size
   test) or split oddly at the image border leaked into the map; static points that close to a
   teammate are seen again once it has moved on.

Everything is pure numpy + Open3D on one frame; the caller zeroes the returned pixel mask, so
only filtered depth reaches the map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common import voxels
from services.common.arrays import unique_groups
from services.common.dbscan import dbscan_labels
from services.common.geometry import invert, transform_points

MAX_VOXELS = 800  # DBSCAN cost grows fast with the point count (field notes: 3 ms at 2k)


@dataclass(frozen=True)
class DrfParams:
    c: float = 0.25  # buffer: c/d rad in awareness, c metres around the robot in the box
    radius_m: float = 0.306  # R, the robot's largest dimension (paper)
    robot_top_m: float = 0.42  # tallest teammate part (mast 0.38 m) + margin
    floor_z_m: float = 0.012  # points at or below are floor, never the robot
    eps_m: float = 0.08  # DBSCAN neighbourhood
    min_points: int = 1  # on voxel centres: connected components within eps
    voxel_m: float = 0.03  # voxelize box points before DBSCAN
    footprint_m: float = 0.21  # half-diagonal of the 0.281 × 0.306 m chassis
    margin_m: float = 0.12  # pose uncertainty around the footprint: removed unconditionally


@dataclass(frozen=True)
class Projection:
    u: float
    v: float
    d: float  # z-depth along the optical axis, m


def target_in_base(
    pose_obs: tuple[float, float, float], xy_target: np.ndarray, height_m: float
) -> np.ndarray:
    """(3,) target position in the observer's base frame: R(−ψ)·p_rel, at height h_o."""
    rel = np.asarray(xy_target, dtype=np.float64) - np.array(pose_obs[:2])
    c, s = np.cos(pose_obs[2]), np.sin(pose_obs[2])
    return np.array([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1], height_m])


def project_target(p_base: np.ndarray, K: np.ndarray, T_base_cam: np.ndarray) -> Projection:
    """(u, v, d) of a base-frame point: K · [R_ext | t_ext] · p, then divide by d."""
    p_cam = transform_points(invert(T_base_cam), p_base[None, :])[0]
    uvd = K @ p_cam
    d = float(p_cam[2])
    if d <= 1e-6:
        return Projection(float("nan"), float("nan"), d)
    return Projection(float(uvd[0] / d), float(uvd[1] / d), d)


def _pixel_window(
    proj: Projection, K: np.ndarray, shape: tuple[int, int], half_m: float, top_dz_m: float
) -> tuple[slice, slice]:
    """Image rows/cols that can hold a point of the box (its nearest face bounds the size)."""
    H, W = shape
    near = max(proj.d - half_m, 0.05)
    hw = K[0, 0] * half_m / near + 1
    top = K[1, 1] * top_dz_m / near + 1  # rows above the projected centre
    cols = slice(max(0, int(np.floor(proj.u - hw))), min(W, int(np.ceil(proj.u + hw)) + 1))
    rows = slice(max(0, int(np.floor(proj.v - top))), H)  # down to the image bottom (floor)
    return rows, cols


def _window_points(
    depth_m: np.ndarray, K: np.ndarray, T_base_cam: np.ndarray, rows: slice, cols: slice
) -> tuple[np.ndarray, np.ndarray]:
    """Base-frame points of the window's valid pixels and their flat pixel indices."""
    win = depth_m[rows, cols]
    r, c = np.nonzero(win > 0)
    z = win[r, c].astype(np.float64)
    r, c = r + rows.start, c + cols.start
    pts_cam = np.stack([(c - K[0, 2]) * z / K[0, 0], (r - K[1, 2]) * z / K[1, 1], z], 1)
    return transform_points(T_base_cam, pts_cam), r * depth_m.shape[1] + c


def _in_box(points_base: np.ndarray, centre_base: np.ndarray, params: DrfParams) -> np.ndarray:
    """Points within R + c of the centre along and across its line of sight, above the floor."""
    half = params.radius_m + params.c
    axis = centre_base[:2] / max(float(np.hypot(*centre_base[:2])), 1e-9)
    rel = points_base[:, :2] - centre_base[None, :2]
    along = rel @ axis
    across = rel @ np.array([-axis[1], axis[0]])
    z = points_base[:, 2]
    return (
        (np.abs(along) <= half) & (np.abs(across) <= half)
        & (z > params.floor_z_m) & (z <= params.robot_top_m)
    )


def in_footprint(points_base: np.ndarray, centre_xy: np.ndarray, params: DrfParams) -> np.ndarray:
    """(N,) bool: points within the footprint grown by the pose margin (box points only)."""
    reach = params.footprint_m + params.margin_m
    return np.hypot(*(points_base[:, :2] - centre_xy[None, :]).T) <= reach


def robot_cluster(
    points_base: np.ndarray, centre_xy: np.ndarray, params: DrfParams
) -> np.ndarray:
    """(N,) bool: the points of the robot-sized DBSCAN clusters near the expected position."""
    if points_base.shape[0] == 0:
        return np.zeros(0, bool)
    keys = voxels.pack(voxels.voxel_indices(points_base, params.voxel_m))
    _, first, inverse, _ = unique_groups(keys)
    if first.size > MAX_VOXELS:  # a robot right in front of the lens: coarser voxels
        keys = voxels.pack(voxels.voxel_indices(points_base, 2 * params.voxel_m))
        _, first, inverse, _ = unique_groups(keys)
    reps = points_base[first]
    labels = dbscan_labels(reps, params.eps_m, params.min_points)
    clustered = labels >= 0
    robot = np.zeros(labels.shape, bool)
    keep = _robot_sized(reps[clustered, :2], labels[clustered], centre_xy, params)
    robot[clustered] = keep[labels[clustered]]
    return robot[inverse.reshape(-1)]


def _robot_sized(
    xy: np.ndarray, labels: np.ndarray, centre_xy: np.ndarray, params: DrfParams
) -> np.ndarray:
    """(max label + 1,) bool per cluster (labels ≥ 0): near the expected position and of the
    robot's size. Per-cluster minima and maxima, so the same floats as a loop over clusters."""
    n_labels = int(labels.max()) + 1 if labels.size else 0
    gap = np.full(n_labels, np.inf)
    np.minimum.at(gap, labels, np.hypot(*(xy - centre_xy[None, :]).T))
    lo = np.full((n_labels, 2), np.inf)
    hi = np.full((n_labels, 2), -np.inf)
    np.minimum.at(lo, labels, xy)
    np.maximum.at(hi, labels, xy)
    diag = np.hypot(*(hi - lo).T)
    fits = diag <= 2 * params.radius_m + 2 * params.voxel_m
    return (gap <= params.radius_m + params.c) & fits


def filter_mask(
    depth_m: np.ndarray, K: np.ndarray, T_base_cam: np.ndarray,
    pose_obs: tuple[float, float, float], xy_targets: np.ndarray, params: DrfParams,
) -> np.ndarray:
    """(H, W) bool: pixels to drop, the union of every in-view target's robot cluster."""
    mask = np.zeros(depth_m.shape, bool)
    height = float(T_base_cam[2, 3])  # h_o, the observer's camera height
    for xy in np.asarray(xy_targets, dtype=np.float64).reshape(-1, 2):
        centre = target_in_base(pose_obs, xy, height)
        proj = project_target(centre, K, T_base_cam)
        half = params.radius_m + params.c
        if np.isfinite(proj.u) and proj.d > half:
            rows, cols = _pixel_window(proj, K, depth_m.shape, half, params.robot_top_m - height)
        else:  # centre beside or behind the lens: a very close robot may fill any part
            rows, cols = slice(0, depth_m.shape[0]), slice(0, depth_m.shape[1])
        if rows.stop <= rows.start or cols.stop <= cols.start:
            continue
        pts, flat = _window_points(depth_m, K, T_base_cam, rows, cols)
        box = _in_box(pts, centre, params)
        robot = robot_cluster(pts[box], centre[:2], params)
        robot |= in_footprint(pts[box], centre[:2], params)
        mask.reshape(-1)[flat[box][robot]] = True
    return mask
