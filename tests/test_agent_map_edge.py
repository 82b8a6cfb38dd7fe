"""A frame that reaches past the far edge of the registration map registers behind.

Synthetic aisle: two rack faces with uprights every 2.7 m, seen by a 5 m camera with the
simulator's realistic depth noise (σ = 0.0005·d² along the ray). The robot drives 6 m in
10 cm steps on perfect odometry; each frame is registered and joins the map at the pose found,
so a bias per registration adds up. Aligning only the points within 4 m (the map reaches
about 5 m ahead of the last frame) halves the drift: the far edge's half-seen voxels pulled.
"""

from __future__ import annotations

import numpy as np

from services.common.geometry import T_from_xyyaw, xyyaw_from_T
from services.robot_agent.drift_filter import FilterParams
from services.robot_agent.localization import Localizer
from services.robot_agent.registrar import FrameRegistrar, RegistrationParams
from services.robot_agent.synthetic import aisle_frame, aisle_points


def _drift_over_6_m(align_range_m: float) -> float:
    world = aisle_points(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    reg = FrameRegistrar(RegistrationParams(map_voxel_m=0.05))
    est = 0.0
    for i, x in enumerate(np.arange(0.0, 6.01, 0.1)):
        points = aisle_frame(world, x, rng)
        cloud = reg.cloud_tree(points)[0]
        if i:
            near = np.hypot(points[:, 0], points[:, 1]) <= align_range_m
            aligned = reg.align(reg.cloud_tree(points[near])[0] if align_range_m else cloud,
                                T_from_xyyaw(est + 0.1, 0.0, 0.0))
            assert not isinstance(aligned, str)
            est = xyyaw_from_T(aligned[0])[0]
        reg.insert(cloud, T_from_xyyaw(est, 0.0, 0.0))
    return est - 6.0


def test_aligning_inside_the_map_halves_the_drift_along_an_aisle() -> None:
    whole, inside = _drift_over_6_m(0.0), _drift_over_6_m(4.0)
    assert whole < -0.02  # the whole frame: the chain lags 2-3 cm over 6 m
    assert abs(inside) < 0.6 * abs(whole)


def test_the_localizer_aligns_the_near_points_and_maps_them_all() -> None:
    points = aisle_frame(aisle_points(np.random.default_rng(0)), 0.0, np.random.default_rng(1))
    whole = Localizer(RegistrationParams(filter=FilterParams()))
    assert whole._align_cloud(points) is None  # 0: the frame registers whole
    near = Localizer(RegistrationParams(filter=FilterParams(), align_max_range_m=3.0))
    cloud = near._align_cloud(points)
    assert cloud is not None
    assert np.hypot(cloud.points()[:, 0], cloud.points()[:, 1]).max() <= 3.0
    full = near.registrar.cloud_tree(points)[0]
    assert np.hypot(full.points()[:, 0], full.points()[:, 1]).max() > 4.5


def test_the_localizer_aligns_the_points_inside_a_bearing_and_maps_them_all() -> None:
    points = aisle_frame(aisle_points(np.random.default_rng(0)), 0.0, np.random.default_rng(1))
    narrow = Localizer(RegistrationParams(filter=FilterParams(),
                                          align_max_bearing_rad=np.radians(30.0)))
    cloud = narrow._align_cloud(points)
    assert cloud is not None
    bearing = np.abs(np.arctan2(cloud.points()[:, 1], cloud.points()[:, 0]))
    assert bearing.max() <= np.radians(30.0) + 0.02  # voxel means of the points kept
    full = narrow.registrar.cloud_tree(points)[0]
    assert np.abs(np.arctan2(full.points()[:, 1], full.points()[:, 0])).max() > np.radians(38.0)


def test_more_neighbors_give_smoother_normals_to_the_far_noisy_points() -> None:
    points = aisle_frame(aisle_points(np.random.default_rng(0)), 0.0, np.random.default_rng(1))
    far = np.hypot(points[:, 0], points[:, 1]) > 4.0

    def normal_spread(neighbors: int) -> float:
        cloud = FrameRegistrar(RegistrationParams(neighbors=neighbors)).cloud_tree(points[far])
        assert cloud is not None
        normals = cloud[0].normals()[:, :3]
        on_wall = np.abs(normals[:, 1]) > 0.5  # the rack faces' normals point across the aisle
        return float(np.std(normals[on_wall, 0]))  # their along-aisle tilt

    assert normal_spread(20) < normal_spread(10)
