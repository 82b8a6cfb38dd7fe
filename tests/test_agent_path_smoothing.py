"""Path smoothing: A*'s staircase cut along lines of sight, never through a blocked cell."""

from __future__ import annotations

import numpy as np

from services.common.grid import GridSpec
from services.common.planning import astar
from services.robot_agent.navigation import plan_path
from services.robot_agent.path_smoothing import line_of_sight, shortcut_waypoints, smooth_path


def headings(path: np.ndarray) -> np.ndarray:
    d = np.diff(path, axis=0)
    return np.degrees(np.arctan2(d[:, 0], d[:, 1]))


def test_open_ground_becomes_one_straight_segment() -> None:
    free = np.ones((40, 60), bool)
    path = astar(free, (2, 2), (30, 55))
    assert path is not None and len(np.unique(np.round(headings(path)))) == 2  # 0° and 45°
    corners = shortcut_waypoints(free, path)
    assert np.array_equal(corners, [[2, 2], [30, 55]])
    smooth = smooth_path(free, path)
    assert np.allclose(smooth[0], [2, 2]) and np.allclose(smooth[-1], [30, 55])
    assert np.ptp(headings(smooth)) < 1e-6  # one heading all along
    assert np.hypot(*np.diff(smooth, axis=0).T).max() <= 1.0 + 1e-9  # as dense as A*'s


def test_the_path_bends_around_a_wall_and_never_crosses_it() -> None:
    free = np.ones((40, 40), bool)
    free[5:40, 20] = False  # a wall with a gap at the top
    path = astar(free, (35, 5), (35, 35))
    assert path is not None
    smooth = smooth_path(free, path)
    cells = np.floor(smooth + 0.5).astype(int)
    assert free[cells[:, 0], cells[:, 1]].all()
    corners = shortcut_waypoints(free, path)
    assert 3 <= len(corners) <= 4  # start, around the wall's end, goal
    steps = np.hypot(*np.diff(smooth, axis=0).T).sum()
    assert steps < np.hypot(*np.diff(path, axis=0).T).sum()  # shorter than A*'s staircase
    for a, b in zip(corners[:-1], corners[1:], strict=True):
        assert line_of_sight(free, a, b)


def test_line_of_sight_sees_a_single_blocked_cell_between_diagonal_corners() -> None:
    free = np.ones((10, 10), bool)
    free[4, 5] = False
    assert not line_of_sight(free, np.array([0, 1]), np.array([9, 9]))
    assert line_of_sight(free, np.array([0, 0]), np.array([9, 0]))


def test_plan_path_smooth_keeps_its_ends() -> None:
    spec = GridSpec(0.0, 0.0, 0.05, 60, 80)
    free = np.ones(spec.shape, bool)
    free[10:60, 40] = False
    start, goal = np.array([0.5, 2.5]), np.array([3.5, 2.0])
    raw = plan_path(free, spec, start, goal, 0.6)
    smooth = plan_path(free, spec, start, goal, 0.6, smooth=True)
    assert raw.path_xy is not None and smooth.path_xy is not None
    assert np.allclose(raw.path_xy[[0, -1]], smooth.path_xy[[0, -1]])
    def length(xy: np.ndarray) -> float:
        return float(np.hypot(*np.diff(xy, axis=0).T).sum())
    assert length(smooth.path_xy) < length(raw.path_xy)
