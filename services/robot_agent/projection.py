"""Depth image → 3D points, and the camera → base → world chain.

Frames: `cam` is the optical frame (x right, y down, z forward), `base` the robot base on the
floor (z up), `world` the mission frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.common.geometry import transform_points


@dataclass(frozen=True)
class CameraPoints:
    """Valid depth pixels of one frame as points in the optical frame."""

    points_cam: np.ndarray  # (N, 3) float64
    rows: np.ndarray  # (N,) int64 pixel row
    cols: np.ndarray  # (N,) int64 pixel column


def depth_to_points(
    depth_m: np.ndarray, K: np.ndarray, stride: int = 1, range_max_m: float | None = None
) -> CameraPoints:
    """Back-project every `stride`-th pixel with a return (0 < depth ≤ range) to 3D."""
    depth = np.asarray(depth_m)[::stride, ::stride]
    valid = np.isfinite(depth) & (depth > 0)
    if range_max_m is not None:
        valid &= depth <= range_max_m
    r_sub, c_sub = np.nonzero(valid)
    rows, cols = r_sub * stride, c_sub * stride
    z = depth[r_sub, c_sub].astype(np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x = (cols - cx) * z / fx
    y = (rows - cy) * z / fy
    return CameraPoints(np.stack([x, y, z], axis=1), rows, cols)


def points_to_depth(points_cam: np.ndarray, K: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Render (N, 3) optical-frame points into a z-buffer depth image (0 = no return)."""
    H, W = shape
    depth = np.zeros((H, W), dtype=np.float32)
    z = points_cam[:, 2]
    front = z > 0
    u = np.round(K[0, 0] * points_cam[front, 0] / z[front] + K[0, 2]).astype(np.int64)
    v = np.round(K[1, 1] * points_cam[front, 1] / z[front] + K[1, 2]).astype(np.int64)
    zf = z[front]
    inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    u, v, zf = u[inside], v[inside], zf[inside]
    order = np.argsort(-zf)  # far first, so the nearest point is written last
    depth[v[order], u[order]] = zf[order]
    return depth


def cam_to_base(points_cam: np.ndarray, T_base_cam: np.ndarray) -> np.ndarray:
    """(N, 3) optical-frame points → robot base frame."""
    return transform_points(T_base_cam, points_cam)


def base_to_frame(points_base: np.ndarray, T_frame_base: np.ndarray) -> np.ndarray:
    """(N, 3) base-frame points → any frame whose pose of the base is `T_frame_base`."""
    return transform_points(T_frame_base, points_base)


def pixel_colors(rgb: np.ndarray, cam_points: CameraPoints) -> np.ndarray:
    """(N, 3) uint8 colours of the pixels behind `cam_points`."""
    return np.asarray(rgb)[cam_points.rows, cam_points.cols]


def hfov_of(K: np.ndarray, width: int) -> float:
    """Horizontal field of view of a pinhole camera, rad."""
    return 2.0 * math.atan2(width / 2.0, K[0, 0])


def intrinsics(width: int, height: int, hfov_rad: float) -> np.ndarray:
    """Square-pixel pinhole K for a horizontal field of view (tests and benches)."""
    f = (width / 2.0) / np.tan(hfov_rad / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def optical_to_base_rotation() -> np.ndarray:
    """Rotation of a forward-looking optical frame in the base frame (z fwd → base x)."""
    return np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def T_base_cam_forward(height_m: float, forward_m: float = 0.0) -> np.ndarray:
    """Extrinsics of a level, forward-looking camera at `height_m` (tests and benches)."""
    T = np.eye(4)
    T[:3, :3] = optical_to_base_rotation()
    T[:3, 3] = (forward_m, 0.0, height_m)
    return T
