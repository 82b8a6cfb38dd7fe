"""Registration keeps the points of the map voxels the view saw whole (view_voxels.py), in
the agent only while its registrations are lopsided when asked."""

from __future__ import annotations

import math

import numpy as np
import pytest

from schemas.messages import RgbdFrame
from services.common.geometry import T_from_xyyaw, xyyaw_from_T
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.projection import (
    T_base_cam_forward,
    cam_to_base,
    depth_to_points,
    intrinsics,
)
from services.robot_agent.registrar import FrameRegistrar, RegistrationParams
from services.robot_agent.synthetic import (
    BoxWorld,
    T_world_cam_of,
    aisle_frame,
    aisle_points,
    render,
)
from services.robot_agent.view_voxels import CameraView, corners_inside, whole_voxel_mask

# a forward camera 0.2 m up: optical z along base x, optical x along −base y, y along −z
T_BASE_CAM = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.2],
                       [0.0, 0.0, 0.0, 1.0]])
K = np.array([[80.0, 0.0, 79.5], [0.0, 80.0, 59.5], [0.0, 0.0, 1.0]])
VIEW = CameraView(K, 160, 120, 5.0, T_BASE_CAM)


def test_the_camera_view_holds_what_the_image_and_range_hold() -> None:
    points_base = np.array([[2.0, 0.0, 0.2],  # straight ahead
                            [5.5, 0.0, 0.2],  # beyond the range
                            [-1.0, 0.0, 0.2],  # behind
                            [1.0, 1.5, 0.2],  # left of the 90° image (45° half angle)
                            [1.0, 0.9, 0.2]])  # just inside it
    corners_at = np.zeros((8, 3))  # a point as a voxel of no size
    assert VIEW.holds_whole(points_base, corners_at).tolist() == [True, False, False, False, True]


def test_points_of_voxels_the_range_cuts_are_left_out() -> None:
    # a wall across the view at 4.98 m: its 5 cm voxels span 4.95-5.00 (whole) and a row of
    # points at 5.02 m would sit in 5.00-5.05 voxels, cut by the 5 m range
    y, z = np.meshgrid(np.linspace(-0.5, 0.5, 21), np.linspace(0.1, 0.5, 9))
    wall = np.stack([np.full(y.size, 4.98), y.ravel(), z.ravel()], axis=1)
    beyond = wall + [0.04, 0.0, 0.0]
    mask = whole_voxel_mask(np.concatenate([wall, beyond]), np.eye(4), 0.05, VIEW.holds_whole)
    assert mask[: len(wall)].all() and not mask[len(wall):].any()


def test_the_voxel_grid_is_the_map_frame_s() -> None:
    # the same base-frame point, with the base 3 cm further on: its map voxel moves across the
    # range's edge
    point = np.array([[4.97, 0.0, 0.22]])
    assert whole_voxel_mask(point, np.eye(4), 0.05, VIEW.holds_whole).all()
    assert not whole_voxel_mask(point, T_from_xyyaw(0.03, 0.0, 0.0), 0.05, VIEW.holds_whole).any()


def test_a_voxel_over_pixels_without_a_return_is_cut() -> None:
    y, z = np.meshgrid(np.linspace(-0.5, 0.5, 41), np.linspace(0.1, 0.3, 9))
    wall = np.stack([np.full(y.size, 2.98), y.ravel(), z.ravel()], axis=1)
    valid = np.ones((120, 160), bool)
    every = CameraView(K, 160, 120, 5.0, T_BASE_CAM, valid)
    assert whole_voxel_mask(wall, np.eye(4), 0.05, every.holds_whole).all()
    valid[:, 80:] = False  # no returns right of the centre (base −y): grazing, say
    half = CameraView(K, 160, 120, 5.0, T_BASE_CAM, valid)
    mask = whole_voxel_mask(wall, np.eye(4), 0.05, half.holds_whole)
    assert mask[wall[:, 1] > 0.05].all() and not mask[wall[:, 1] < 0.0].any()


def test_the_bounding_sphere_is_stricter_at_the_range() -> None:
    # a voxel whose corners lie within the 5 m range but whose bounding sphere (radius
    # √3/2 · 5 cm ≈ 4.3 cm) reaches past it
    valid = np.ones((120, 160), bool)
    corners = CameraView(K, 160, 120, 5.0, T_BASE_CAM, valid)
    sphere = CameraView(K, 160, 120, 5.0, T_BASE_CAM, valid, sphere=True)
    near, edge = np.array([[4.0, 0.0, 0.22]]), np.array([[4.97, 0.0, 0.22]])
    shift = T_from_xyyaw(0.0, 0.0, 0.0)
    assert whole_voxel_mask(edge, shift, 0.05, corners.holds_whole).all()
    assert not whole_voxel_mask(edge, shift, 0.05, sphere.holds_whole).any()
    assert whole_voxel_mask(near, shift, 0.05, sphere.holds_whole).all()
    valid[:, :] = False  # no returns at all: nothing is whole either way
    none = CameraView(K, 160, 120, 5.0, T_BASE_CAM, valid, sphere=True)
    assert not whole_voxel_mask(near, shift, 0.05, none.holds_whole).any()


def test_bad_input_is_refused_or_empty() -> None:
    assert whole_voxel_mask(np.empty((0, 3)), np.eye(4), 0.05, VIEW.holds_whole).shape == (0,)
    with pytest.raises(ValueError, match="voxel_m"):
        whole_voxel_mask(np.zeros((1, 3)), np.eye(4), 0.0, VIEW.holds_whole)


def _aisle_view(points_base: np.ndarray) -> np.ndarray:
    """synthetic.aisle_frame's view: 0.3-5 m, 42° either side."""
    r = np.hypot(points_base[:, 0], points_base[:, 1])
    return (points_base[:, 0] > 0.3) & (r < 5.0) & (
        np.abs(np.arctan2(points_base[:, 1], points_base[:, 0])) < np.radians(42.0))


def _lag_over_6_m(whole: bool) -> float:
    world = aisle_points(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    reg = FrameRegistrar(RegistrationParams(map_voxel_m=0.05))
    est = 0.0
    for i, x in enumerate(np.arange(0.0, 6.01, 0.1)):
        points = aisle_frame(world, x, rng)
        guess = T_from_xyyaw(est + 0.1 if i else 0.0, 0.0, 0.0)
        if whole:
            points = points[whole_voxel_mask(points, guess, 0.05, corners_inside(_aisle_view))]
        cloud = reg.cloud_tree(points)[0]
        if i:
            aligned = reg.align(cloud, guess)
            assert not isinstance(aligned, str)
            est = xyyaw_from_T(aligned[0])[0]
        reg.insert(cloud, T_from_xyyaw(est, 0.0, 0.0))
    return est - 6.0


def test_whole_voxels_take_most_of_the_lag_out_of_an_aisle() -> None:
    every, whole = _lag_over_6_m(False), _lag_over_6_m(True)
    assert every < -0.02  # all points: the chain lags 2-3 cm over 6 m
    assert abs(whole) < 0.6 * abs(every)


def test_the_agent_cuts_only_while_its_registrations_are_lopsided() -> None:
    K_, T_ = intrinsics(160, 120, math.radians(84.1)), T_base_cam_forward(0.35)
    world = BoxWorld.room(-3.0, 7.0, -1.2, 1.2)  # a corridor longer than the range
    depth, rgb = render(world, K_, (120, 160), T_world_cam_of(0.0, 0.0, 0.0, T_), 5.0)
    frame = RgbdFrame(robot_id=0, tick=0, stamp_ns=0, depth_m=depth, rgb=rgb, K=K_,
                      T_base_cam=T_, range_max_m=5.0)
    points_base = cam_to_base(depth_to_points(depth, K_).points_cam, T_)
    core = AgentCore(AgentConfig(reg_whole_voxels="sphere", reg_whole_voxels_below_ratio=0.05),
                     0, 0.1)
    kept = {}
    for ratio in (1.0, 0.5, 0.01):
        core.localizer.info_ratio = ratio
        kept[ratio] = len(core._whole_voxels(points_base, frame, np.eye(4)))
    assert kept[1.0] == kept[0.5] == len(points_base)  # well held: every point registers
    assert 0.5 * len(points_base) < kept[0.01] < len(points_base)  # the cut layer goes
    always = AgentCore(AgentConfig(reg_whole_voxels="sphere"), 0, 0.1)
    always.localizer.info_ratio = 1.0
    assert len(always._whole_voxels(points_base, frame, np.eye(4))) == kept[0.01]
