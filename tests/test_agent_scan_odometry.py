"""The heading change between consecutive frames, from the frames (scan_odometry.py)."""

from __future__ import annotations

import math

import numpy as np
import small_gicp

from services.common.geometry import T_from_xyyaw, invert, transform_points, xyyaw_from_T
from services.robot_agent.drift_filter import FilterParams
from services.robot_agent.localization import Localizer
from services.robot_agent.registrar import RegistrationParams
from services.robot_agent.scan_odometry import ScanOdometry, ScanOdometryParams
from tests.test_agent_localization import _wall


def _hall(rng: np.random.Generator) -> np.ndarray:
    return np.concatenate([_wall(-4, -3, 4.5, -3, rng), _wall(-4, 3, 4.5, 3, rng),
                           _wall(-4, -3, -4, 3, rng), _wall(4.5, -3, 4.5, 3, rng),
                           _wall(3, -3, 3, -1.5, rng), _wall(2.5, 1.0, 3.5, 1.6, rng),
                           _wall(1, 3, 1, 2.2, rng)])


def _camera_view(points_world: np.ndarray, T_world_base: np.ndarray) -> np.ndarray:
    """Points in the base frame inside an 84° field of view and 5 m (a Kinect's)."""
    p = transform_points(invert(T_world_base), points_world)
    bearing = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    return p[(np.abs(bearing) < 42.0) & (np.linalg.norm(p[:, :2], axis=1) < 5.0)]


def _frame(points_base: np.ndarray) -> tuple[small_gicp.PointCloud, small_gicp.KdTree]:
    return small_gicp.preprocess_points(points_base, 0.08, num_neighbors=10, num_threads=1)


def test_two_frames_give_the_turn_odometry_got_wrong() -> None:
    """A 9° step of a turn in place (one camera frame at 45°/s), odometry 0.4° off."""
    hall = _hall(np.random.default_rng(3))
    scans = ScanOdometry(ScanOdometryParams())
    T0, T1 = T_from_xyyaw(0.0, 0.0, 0.5), T_from_xyyaw(0.0, 0.0, 0.5 + math.radians(9.0))
    assert scans.turn(*_frame(_camera_view(hall, T0)), T0) is None  # nothing to compare yet
    odom1 = T_from_xyyaw(0.0, 0.0, 0.5 + math.radians(9.4))
    turn = scans.turn(*_frame(_camera_view(hall, T1)), odom1)
    assert turn is not None and abs(math.degrees(turn) - 9.0) < 0.05
    # a turn odometry cannot have made (3° off on 9°) is not taken: a wrong basin, or a
    # frame of something else
    T2 = T_from_xyyaw(0.0, 0.0, 0.5 + math.radians(18.0))
    assert scans.turn(*_frame(_camera_view(hall, T2)), T2 @ T_from_xyyaw(0, 0, 0.2)) is None
    scans.reset()
    assert scans.turn(*_frame(_camera_view(hall, T2)), T2) is None


def test_a_frame_the_map_cannot_register_keeps_the_frames_heading() -> None:
    """Turning into new ground, a frame GICP cannot register against the map keeps the guess;
    with the heading from the previous frame the guess is right, with odometry's it is not."""
    hall = _hall(np.random.default_rng(5))
    T0, T1 = T_from_xyyaw(0.2, -0.3, 0.0), T_from_xyyaw(0.2, -0.3, math.radians(9.0))
    odom1 = T_from_xyyaw(0.2, -0.3, math.radians(9.8))  # the wheels' turn, 0.8° long
    errors = {}
    for scan in (None, ScanOdometryParams()):
        loc = Localizer(RegistrationParams(map_voxel_m=0.05, min_points=30, filter=FilterParams(),
                                           min_inlier_frac=0.15, max_iterations=1,
                                           insert_unconverged=True, scan_odometry=scan))
        loc.update(_camera_view(hall, T0), T0)
        out = loc.update(_camera_view(hall, T1), odom1)
        # with the frames' heading the guess is close enough for GICP's one iteration
        assert out.accepted == (scan is not None) and (scan or out.reason == "not converged")
        errors[scan is not None] = abs(math.degrees(xyyaw_from_T(invert(T1) @ out.T_loc_base)[2]))
    assert errors[False] > 0.79 and errors[True] < 0.05


def test_a_turn_behind_teammates_keeps_the_frames_heading_where_asked() -> None:
    """Frames too hidden to register against the map (the DRF took most of them) are left out
    of it; with `when_hidden` their remains still give the turn, so a turn behind teammates
    does not carry odometry's error (1-1.5° in six-robot missions)."""
    hall = _hall(np.random.default_rng(7))
    poses = [T_from_xyyaw(0.1, 0.2, math.radians(9.0 * k)) for k in range(5)]
    odoms = [T_from_xyyaw(0.1, 0.2, math.radians(9.3 * k)) for k in range(5)]  # 3.3 % long
    errors = {}
    for when_hidden in (False, True):
        loc = Localizer(RegistrationParams(min_points=30, filter=FilterParams(),
                                           scan_odometry=ScanOdometryParams(
                                               when_hidden=when_hidden)))
        out = loc.update(_camera_view(hall, poses[0]), odoms[0])
        for T, odom in zip(poses[1:], odoms[1:], strict=True):
            out = loc.update(_camera_view(hall, T), odom, removed_frac=0.6)
            assert not out.accepted and out.reason == "hidden by teammates"
        assert loc.registrar.n_inserted == 1  # nothing hidden joins the map
        errors[when_hidden] = abs(math.degrees(xyyaw_from_T(invert(poses[-1]) @ out.T_loc_base)[2]))
    assert errors[False] > 1.1 and errors[True] < 0.1
