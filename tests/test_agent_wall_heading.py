"""Absolute heading from wall directions (wall_heading.py)."""

from __future__ import annotations

import math

import numpy as np
import small_gicp

from services.common.geometry import T_from_xyyaw, invert, transform_points
from services.robot_agent.wall_heading import (
    WallHeading,
    WallHeadingParams,
    fold,
    fuse_heading,
    wall_direction,
)
from tests.test_agent_localization import _wall

PARAMS = WallHeadingParams()


def _rotated(points: np.ndarray, yaw_deg: float) -> np.ndarray:
    return transform_points(T_from_xyyaw(0.0, 0.0, math.radians(yaw_deg)), points)


def _room(rng: np.random.Generator, noise_m: float = 0.005) -> np.ndarray:
    pts = np.concatenate([_wall(-3, -2, 3, -2, rng), _wall(-3, 2, 3, 2, rng),
                          _wall(-3, -2, -3, 2, rng), _wall(3, -2, 3, 2, rng)])
    return pts + rng.normal(0.0, noise_m, pts.shape)


def _frame(points_world: np.ndarray, xyyaw: tuple[float, float, float],
           ) -> tuple[np.ndarray, np.ndarray]:
    """The points a robot at `xyyaw` sees (all around, 4 m), downsampled as the registrar
    does: base-frame points (N, 3) and their covariances (N, 3, 3)."""
    p = transform_points(invert(T_from_xyyaw(*xyyaw)), points_world)
    p = p[np.linalg.norm(p[:, :2], axis=1) < 4.0]
    cloud, _ = small_gicp.preprocess_points(p, 0.08, num_neighbors=10, num_threads=1)
    return cloud.points()[:, :3], np.asarray(cloud.covs())[:, :3, :3]


def test_a_frame_gives_its_walls_direction_modulo_90_degrees() -> None:
    rng = np.random.default_rng(0)
    room = _rotated(_room(rng), 17.0)
    for yaw_deg in (0.0, 31.0, -100.0):
        d = wall_direction(*_frame(room, (0.3, -0.2, math.radians(yaw_deg))), PARAMS)
        assert d is not None
        expected = fold(math.radians(17.0 - yaw_deg))
        assert abs(math.degrees(fold(d.angle_rad - expected))) < 0.05


def test_floor_only_gives_nothing() -> None:
    rng = np.random.default_rng(1)
    floor = np.column_stack([rng.uniform(-3, 3, 20000), rng.uniform(-3, 3, 20000),
                             rng.normal(0.0, 0.003, 20000) + 0.2])
    assert wall_direction(*_frame(floor, (0.0, 0.0, 0.0)), PARAMS) is None


def test_one_long_rotated_thing_does_not_set_the_direction() -> None:
    """Short walls and a long straight cabinet 2° off them: the segments' fit follows the
    cabinet, the points' directions do not, and a frame they disagree on gives nothing."""
    rng = np.random.default_rng(2)
    corner = np.concatenate([_wall(1.0, 1.0, 2.0, 1.0, rng), _wall(2.0, -0.2, 2.0, 1.0, rng)])
    a = math.radians(2.0)
    cabinet = _wall(-1.5, -1.5, -1.5 + 3.5 * math.cos(a), -1.5 + 3.5 * math.sin(a), rng)
    pts = np.concatenate([corner, cabinet])
    pts = pts + rng.normal(0.0, 0.003, pts.shape)
    assert wall_direction(*_frame(pts, (0.0, 0.0, 0.0)), PARAMS) is None
    # the same walls without the cabinet do give one
    alone = wall_direction(*_frame(corner + rng.normal(0, 0.003, corner.shape), (0.0, 0.0, 0.0)),
                           PARAMS)
    assert alone is not None and abs(math.degrees(alone.angle_rad)) < 0.1


def test_a_heading_pulls_yaw_and_the_position_its_error_swung() -> None:
    P = np.array([[1e-4, 0.0, 0.0], [0.0, 1e-4, 2e-4], [0.0, 2e-4, math.radians(1.0) ** 2]])
    out = fuse_heading(np.zeros(3), P, math.radians(0.8), math.radians(0.1), 10.83)
    assert out.accepted
    assert math.radians(0.7) < out.xyyaw[2] < math.radians(0.8)
    assert out.xyyaw[1] > 0.005 and out.xyyaw[0] == 0.0  # y correlated with yaw, x not
    assert out.P[2, 2] < math.radians(0.1) ** 2
    far = fuse_heading(np.zeros(3), P, math.radians(10.0), math.radians(0.1), 10.83)
    assert not far.accepted and np.all(far.xyyaw == 0.0)


def test_learned_at_the_start_the_walls_bring_a_lost_turn_back() -> None:
    """The start pose is known: the world's direction is learned there. After a 90° turn that
    odometry got 1° wrong, the walls give the heading back to a few hundredths of a degree;
    the whole room turned 10° (not this world's walls) is rejected."""
    rng = np.random.default_rng(3)
    room = _rotated(_room(rng), 5.0)
    walls = WallHeading(PARAMS)
    start = np.array([0.0, 0.0, 0.0])
    xyyaw, P = walls.update(start, np.zeros((3, 3)), *_frame(room, tuple(start)))
    assert walls.world_rad is not None and abs(math.degrees(walls.world_rad) - 5.0) < 0.05
    for _ in range(PARAMS.learn_frames):  # the rest of the frames it learns from
        walls.update(start, np.zeros((3, 3)), *_frame(room, tuple(start)))
    truth = (0.5, 0.3, math.radians(90.0))
    guess = np.array([0.5, 0.3, math.radians(91.0)])
    P = np.diag([1e-4, 1e-4, math.radians(1.0) ** 2])
    xyyaw, P = walls.update(guess, P, *_frame(room, truth))
    assert abs(math.degrees(xyyaw[2] - truth[2])) < 0.05
    other = _rotated(_room(rng), 15.0)
    kept, _ = walls.update(guess, np.diag([1e-4, 1e-4, math.radians(1.0) ** 2]),
                           *_frame(other, truth))
    assert np.all(kept == guess) and walls.n_rejected == 1
