"""Frame-to-map registration: degenerate directions keep odometry, a closed room corrects all."""

from __future__ import annotations

import math

import numpy as np
import pytest
import small_gicp

from services.common.geometry import T_from_xyyaw, invert, transform_points, xyyaw_from_T
from services.robot_agent.drift_filter import (
    FilterParams,
    drop_weak_translation,
    translation_information_ratio,
)
from services.robot_agent.localization import Localizer
from services.robot_agent.registrar import RegistrationParams


def _wall(x0: float, y0: float, x1: float, y1: float, rng: np.random.Generator) -> np.ndarray:
    """Points on a vertical wall from (x0, y0) to (x1, y1), 0.05-2 m high, ~2 cm apart."""
    n = int(math.hypot(x1 - x0, y1 - y0) / 0.02) * 100
    s, z = rng.random(n), rng.uniform(0.05, 2.0, n)
    return np.stack([x0 + s * (x1 - x0), y0 + s * (y1 - y0), z], 1)


def _corridor(rng: np.random.Generator) -> np.ndarray:
    return np.concatenate([_wall(-10, -1, 10, -1, rng), _wall(-10, 1, 10, 1, rng)])


def _room(rng: np.random.Generator) -> np.ndarray:
    return np.concatenate([_wall(-3, -2, 3, -2, rng), _wall(-3, 2, 3, 2, rng),
                           _wall(-3, -2, -3, 2, rng), _wall(3, -2, 3, 2, rng),
                           _wall(1, -2, 1, -1, rng)])  # a pillar breaks the symmetry


def _seen(points_world: np.ndarray, T_world_base: np.ndarray) -> np.ndarray:
    """Points in the base frame within 4 m (all around: the test needs no camera model)."""
    points_base = transform_points(invert(T_world_base), points_world)
    return points_base[np.linalg.norm(points_base[:, :2], axis=1) < 4.0]


def _hessian(points_world: np.ndarray, T_world_base: np.ndarray) -> np.ndarray:
    target = small_gicp.GaussianVoxelMap(0.05)
    cloud, _ = small_gicp.preprocess_points(points_world, 0.05, num_neighbors=10)
    target.insert(cloud)
    source, _ = small_gicp.preprocess_points(_seen(points_world, T_world_base), 0.08,
                                             num_neighbors=10)
    res = small_gicp.align(target, source, T_world_base, max_correspondence_distance=0.3)
    return res.H


def test_step_along_a_corridor_is_dropped_across_it_kept() -> None:
    rng = np.random.default_rng(0)
    yaw = math.radians(30)  # the aisle runs along world x: at −30° in the body frame
    H = _hessian(_corridor(rng), T_from_xyyaw(0.0, 0.0, yaw))
    along = np.array([math.cos(-yaw), math.sin(-yaw)])
    across = np.array([-along[1], along[0]])
    step = np.array([*(0.06 * along + 0.03 * across), 0.01])
    out = drop_weak_translation(step, H, 0.05)
    assert abs(out[:2] @ along) < 0.003  # the slide along the aisle is gone
    assert abs(out[:2] @ across - step[:2] @ across) < 0.003  # across it kept
    assert out[2] == step[2]


def test_step_in_a_closed_room_is_kept() -> None:
    rng = np.random.default_rng(1)
    H = _hessian(_room(rng), T_from_xyyaw(0.5, 0.3, 0.4))
    step = np.array([0.04, -0.03, 0.01])
    assert np.array_equal(drop_weak_translation(step, H, 0.05), step)


def test_translation_information_is_lopsided_in_a_corridor_only() -> None:
    corridor = translation_information_ratio(
        _hessian(_corridor(np.random.default_rng(0)), T_from_xyyaw(0.0, 0.0, 0.5)))
    room = translation_information_ratio(
        _hessian(_room(np.random.default_rng(1)), T_from_xyyaw(0.5, 0.3, 0.4)))
    assert corridor < 0.05 < room <= 1.0
    assert translation_information_ratio(np.zeros((6, 6))) == 0.0  # nothing measured


def test_localizer_removes_odometry_drift_in_a_room() -> None:
    rng = np.random.default_rng(2)
    room = _room(rng)
    loc = Localizer(RegistrationParams(map_voxel_m=0.05, degenerate_ratio=0.05))
    drift = T_from_xyyaw(0.0, 0.0, 0.0)
    errors = []
    for k in range(40):  # 2 m forward at 5 cm per frame; odometry over-reads by 4 %
        T_world_base = T_from_xyyaw(-1.5 + 0.05 * k, 0.2, 0.05 * math.sin(k / 6))
        if k:
            drift = drift @ T_from_xyyaw(0.002, 0.0, 0.001)
        T_odom_base = T_world_base @ drift
        out = loc.update(_seen(room, T_world_base), T_odom_base)
        x, y, yaw = xyyaw_from_T(invert(T_world_base) @ out.T_loc_base)
        errors.append((math.hypot(x, y), abs(yaw)))
    odom_error = xyyaw_from_T(drift)
    assert math.hypot(*odom_error[:2]) > 0.07  # odometry alone would be 8 cm off ...
    assert max(e for e, _ in errors) < 0.01  # ... registration keeps within 1 cm
    assert max(a for _, a in errors) < math.radians(0.3)


@pytest.mark.parametrize("filt", [None, FilterParams()], ids=["gate", "filter"])
def test_deferred_inserts_reach_the_map_before_the_next_alignment(
        filt: FilterParams | None) -> None:
    """With `defer_inserts` a frame waits outside the registration map until `flush` or the
    next alignment: poses are the same as inserting at once, whether flushed or not."""
    rng = np.random.default_rng(3)
    room = _room(rng)
    frames = [(T_from_xyyaw(-1.5 + 0.05 * k, 0.2, 0.05 * math.sin(k / 6)),
               T_from_xyyaw(0.002 * k, 0.0, 0.001 * k)) for k in range(12)]
    poses = {}
    for mode in ("inline", "flushed", "at alignment"):
        loc = Localizer(RegistrationParams(map_voxel_m=0.05, degenerate_ratio=0.05, filter=filt))
        loc.registrar.defer_inserts = mode != "inline"
        poses[mode] = []
        for T_world_base, drift in frames:
            out = loc.update(_seen(room, T_world_base), T_world_base @ drift)
            poses[mode].append(out.T_loc_base)
            assert (len(loc.registrar.pending) > 0) == (mode != "inline")
            if mode == "flushed":
                loc.registrar.flush()
    assert np.array_equal(np.stack(poses["flushed"]), np.stack(poses["inline"]))
    assert np.array_equal(np.stack(poses["at alignment"]), np.stack(poses["inline"]))
