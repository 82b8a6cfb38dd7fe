"""A frame that reaches past the far edge of the registration map registers behind.

Synthetic aisle: two rack faces with uprights every 2.7 m, seen by a 5 m camera with the
simulator's realistic depth noise (σ = 0.0005·d² along the ray). The robot drives 6 m in
10 cm steps on perfect odometry; each frame is registered and joins the map at the pose found,
so a bias per registration adds up. Aligning only the points within 4 m (the map reaches
about 5 m ahead of the last frame) halves the drift: the far edge's half-seen voxels pulled.
"""

from __future__ import annotations

import numpy as np

from services.common.geometry import T_from_xyyaw, invert, transform_points, xyyaw_from_T
from services.robot_agent.drift_filter import FilterParams
from services.robot_agent.localization import Localizer
from services.robot_agent.registrar import FrameRegistrar, RegistrationParams

RANGE_M = 5.0
NOISE_PER_M2 = 0.0005


def _aisle(rng: np.random.Generator) -> np.ndarray:
    n = 60_000
    faces = np.c_[rng.uniform(-2.0, 20.0, n), rng.choice([-1.2, 1.2], n),
                  rng.uniform(0.05, 1.5, n)]
    uprights = [np.c_[x0 + rng.uniform(0.0, 0.08, 800), side - np.sign(side) *
                      rng.uniform(0.0, 0.08, 800), rng.uniform(0.05, 1.5, 800)]
                for x0 in np.arange(-2.0, 20.0, 2.7) for side in (-1.2, 1.2)]
    return np.vstack([faces, *uprights])


def _frame(world: np.ndarray, x: float, rng: np.random.Generator) -> np.ndarray:
    """Base-frame points a forward camera at (x, 0) sees, with noise along each ray."""
    base = transform_points(invert(T_from_xyyaw(x, 0.0, 0.0)), world)
    r = np.hypot(base[:, 0], base[:, 1])
    seen = base[(base[:, 0] > 0.3) & (r < RANGE_M)
                & (np.abs(np.arctan2(base[:, 1], base[:, 0])) < np.radians(42))]
    d = np.linalg.norm(seen, axis=1, keepdims=True)
    return seen + seen / d * NOISE_PER_M2 * d**2 * rng.standard_normal((len(seen), 1))


def _drift_over_6_m(align_range_m: float) -> float:
    world = _aisle(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    reg = FrameRegistrar(RegistrationParams(map_voxel_m=0.05))
    est = 0.0
    for i, x in enumerate(np.arange(0.0, 6.01, 0.1)):
        points = _frame(world, x, rng)
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
    points = _frame(_aisle(np.random.default_rng(0)), 0.0, np.random.default_rng(1))
    whole = Localizer(RegistrationParams(filter=FilterParams()))
    assert whole._align_cloud(points) is None  # 0: the frame registers whole
    near = Localizer(RegistrationParams(filter=FilterParams(), align_max_range_m=3.0))
    cloud = near._align_cloud(points)
    assert cloud is not None
    assert np.hypot(cloud.points()[:, 0], cloud.points()[:, 1]).max() <= 3.0
    full = near.registrar.cloud_tree(points)[0]
    assert np.hypot(full.points()[:, 0], full.points()[:, 1]).max() > 4.5
