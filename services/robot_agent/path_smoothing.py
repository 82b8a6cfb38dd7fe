"""Straighter paths: an 8-connected A* path shortened along lines of sight.

A* on a grid moves in 0° and 45° steps, so a path toward any other heading alternates straight
and diagonal runs; pure pursuit follows that staircase and the robot weaves (±15° of heading
every few seconds in missions), which costs time and adds the odometry's turn noise. Here each
waypoint jumps to the farthest path cell it can see through traversable cells (cells already
inflated by the robot's radius, so a straight segment keeps the same clearance as A*'s cells),
and the result is resampled at one cell, as dense as A*'s, for pure pursuit, the blocked-path
check and the validator's expected times.
"""

from __future__ import annotations

import math

import numpy as np

LOS_STEP_CELLS = 0.25  # sample spacing along a segment: a blocked cell cannot slip between


def line_of_sight(traversable: np.ndarray, a_rc: np.ndarray, b_rc: np.ndarray) -> bool:
    """Whether every cell the straight segment between two cell centres crosses (sampled
    every LOS_STEP_CELLS) is traversable."""
    a, b = np.asarray(a_rc, np.float64), np.asarray(b_rc, np.float64)
    n = max(1, math.ceil(float(np.abs(b - a).max()) / LOS_STEP_CELLS))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    cells = np.floor(a + t * (b - a) + 0.5).astype(np.int64)  # cell i spans [i - ½, i + ½)
    inside = ((cells >= 0) & (cells < traversable.shape)).all(axis=1)
    return bool(inside.all() and traversable[cells[:, 0], cells[:, 1]].all())


def _farthest_visible(traversable: np.ndarray, path_rc: np.ndarray, i: int) -> int:
    """A path index after i whose cell i sees (the next one at least): probe 2, 4, 8, ...
    ahead, then bisect between the last seen and the first hidden."""
    last = len(path_rc) - 1
    seen, step = i + 1, 2
    hidden = None
    while seen < last:
        j = min(i + step, last)
        if not line_of_sight(traversable, path_rc[i], path_rc[j]):
            hidden = j
            break
        seen, step = j, step * 2
    while hidden is not None and hidden - seen > 1:
        mid = (seen + hidden) // 2
        if line_of_sight(traversable, path_rc[i], path_rc[mid]):
            seen = mid
        else:
            hidden = mid
    return seen


def shortcut_waypoints(traversable: np.ndarray, path_rc: np.ndarray) -> np.ndarray:
    """(M, 2) int64 corners of the path: start, each farthest visible cell in turn, goal."""
    path_rc = np.asarray(path_rc, np.int64).reshape(-1, 2)
    keep = [0]
    while keep[-1] < len(path_rc) - 1:
        keep.append(_farthest_visible(traversable, path_rc, keep[-1]))
    return path_rc[keep]


def resample(waypoints_rc: np.ndarray, spacing_cells: float = 1.0) -> np.ndarray:
    """(K, 2) float (row, col) points along the polyline, at most `spacing_cells` apart, every
    waypoint included."""
    pts = [waypoints_rc[:1].astype(np.float64)]
    for a, b in zip(waypoints_rc[:-1], waypoints_rc[1:], strict=True):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / spacing_cells))
        t = np.arange(1, n + 1, dtype=np.float64)[:, None] / n
        pts.append(a + t * (b - a))
    return np.concatenate(pts)


def smooth_path(traversable: np.ndarray, path_rc: np.ndarray) -> np.ndarray:
    """(K, 2) float (row, col): an A* cell path cut short along lines of sight, resampled."""
    path_rc = np.asarray(path_rc, np.int64).reshape(-1, 2)
    if len(path_rc) < 3:
        return path_rc.astype(np.float64)
    return resample(shortcut_waypoints(traversable, path_rc))
