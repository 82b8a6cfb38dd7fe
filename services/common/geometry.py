"""Rigid transforms in the plane and in 3D (numpy, float64)."""

from __future__ import annotations

import numpy as np


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Map angles to [-π, π)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi if isinstance(
        angle, np.ndarray
    ) else (angle + np.pi) % (2.0 * np.pi) - np.pi


def T_from_xyyaw(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    """4×4 transform of a planar pose (rotation about +z)."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = (x, y, z)
    return T


def xyyaw_from_T(T: np.ndarray) -> tuple[float, float, float]:
    """Planar part (x, y, yaw) of a 4×4 transform."""
    return float(T[0, 3]), float(T[1, 3]), float(np.arctan2(T[1, 0], T[0, 0]))


def transform_points(T_to_from: np.ndarray, points_from: np.ndarray) -> np.ndarray:
    """Apply a 4×4 transform to (N, 3) points."""
    return points_from @ T_to_from[:3, :3].T + T_to_from[:3, 3]


def transform_xy(T_to_from: np.ndarray, xy_from: np.ndarray) -> np.ndarray:
    """Planar part of a transform applied to (N, 2) points."""
    return xy_from @ T_to_from[:2, :2].T + T_to_from[:2, 3]


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4×4 transform."""
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti
