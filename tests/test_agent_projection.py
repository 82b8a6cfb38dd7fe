"""Depth ↔ points round trip and the camera → base → world chain."""

from __future__ import annotations

import numpy as np

from services.common.geometry import T_from_xyyaw, transform_points
from services.robot_agent.projection import (
    T_base_cam_forward,
    base_to_frame,
    cam_to_base,
    depth_to_points,
    intrinsics,
    points_to_depth,
)

K = intrinsics(160, 120, np.deg2rad(84.1))


def test_points_depth_points_round_trip() -> None:
    rng = np.random.default_rng(0)
    # points on pixel centres at random depths: back-projection must give them back exactly
    rows, cols = rng.integers(0, 120, 300), rng.integers(0, 160, 300)
    rows, cols = np.unique(np.stack([rows, cols], 1), axis=0).T
    z = rng.uniform(0.3, 5.0, rows.size)
    pts = np.stack([(cols - K[0, 2]) * z / K[0, 0], (rows - K[1, 2]) * z / K[1, 1], z], 1)
    depth = points_to_depth(pts, K, (120, 160))
    back = depth_to_points(depth, K)
    order = np.lexsort((back.cols, back.rows))
    np.testing.assert_array_equal(back.rows[order], rows)
    np.testing.assert_array_equal(back.cols[order], cols)
    np.testing.assert_allclose(back.points_cam[order], pts, atol=1e-5 * 5)


def test_stride_and_range_drop_pixels() -> None:
    depth = np.full((120, 160), 2.0, np.float32)
    depth[:, :10] = 0.0
    depth[:, 150:] = 9.0
    cp = depth_to_points(depth, K, stride=2, range_max_m=5.0)
    assert cp.points_cam.shape[0] == 60 * (75 - 5)
    assert np.all(cp.rows % 2 == 0) and np.all(cp.cols % 2 == 0)


def test_centre_pixel_maps_ahead_of_the_robot_in_world() -> None:
    T_base_cam = T_base_cam_forward(0.35)
    depth = np.zeros((120, 160), np.float32)
    depth[60, 80] = 2.0  # near the optical axis
    K_c = K.copy()
    K_c[0, 2], K_c[1, 2] = 80.0, 60.0
    pts_base = cam_to_base(depth_to_points(depth, K_c).points_cam, T_base_cam)
    np.testing.assert_allclose(pts_base[0], [2.0, 0.0, 0.35], atol=1e-9)
    T_world_base = T_from_xyyaw(1.0, 2.0, np.pi / 2)
    pts_world = base_to_frame(pts_base, T_world_base)
    np.testing.assert_allclose(pts_world[0], [1.0, 4.0, 0.35], atol=1e-9)
    np.testing.assert_allclose(transform_points(T_world_base, pts_base), pts_world)
